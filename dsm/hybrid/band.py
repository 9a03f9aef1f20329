"""A ray where the map's depth test is close to undecided: ``|d - z1| < k`` texels of depth.

``d`` is the receiver's depth and ``z1`` its nearest texel's stored depth (the case's format), a
texel of depth being the texel's world width at the receiver (the kit's ``"k texel"`` unit). The
simplest rule: the band around the caster's surface where a bias decides, traced instead.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..maps import lookup
from .base import Inputs, Selection

NAME = "band"
SOURCE = "the depth test's undecided band (|d - z1| < k texels)"


@dataclass(frozen=True)
class Params:
    """The band's half-width."""
    k: float = field(default=1.0, metadata={"doc": "band: half-width of the traced band, texels of depth",
                                            "min": 0.0})


def depth_gap_texels(inputs: Inputs) -> np.ndarray:
    """Per receiver, |d - z1| over the texel's world width (float64 from the float32 values)."""
    tap = lookup.nearest_tap(inputs.rx, inputs.smap)
    d, z1, texel = (np.asarray(x.numpy(), np.float64) for x in (inputs.rx.depth, tap.z1, inputs.rx.texel_world))
    return np.abs(d - z1) / texel


def select(inputs: Inputs, params) -> Selection:
    """The receivers whose depth gap is under ``k`` texels, the whole ray."""
    if inputs.n == 0:
        return Selection(np.zeros(0, bool))
    return Selection(depth_gap_texels(inputs) < params.k)
