"""Combined bias: normal offset, then a constant and a clamped slope-scaled depth bias.

The engines' defaults are mixtures of three terms; this scheme holds all three so every
engine preset is one instance of it (:data:`dsm.schemes.PRESETS`). The lookup point first
moves along the receiver's geometric normal by ``normal_offset`` (as :mod:`normal_offset`);
then the receiver is lit when ``d' <= z1 + depth_bias + min(slope_clamp, slope_scale * m)``,
``m`` the caster's depth change per texel step (the ``slope`` layer, as :mod:`slope_scaled`).
The margin is computed in that order: the threshold, then the receiver's depth subtracted.

Each term is optional (0 = off; ``slope_clamp`` defaults to no clamp). Unlike the hardware
depth bias (:mod:`slope_scaled`), the clamp bounds the slope term only.

Cost: ``NEEDS`` is the static upper bound ``{"slope"}``; :func:`needs` gives an instance's own
layers (``slope`` only when ``slope_scale > 0``), which the plan uses, so a map without a
slope-scaled scheme is built without the slope layer.
"""
import math
from dataclasses import dataclass, field

import drjit as dr

from ..core.types import Length

NAME = "combined"
SOURCE = "engine defaults: normal offset + constant + slope-scaled depth bias"
NEEDS = frozenset({"slope"})
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False


@dataclass(frozen=True)
class Params:
    """Combined bias's parameters: normal offset, constant depth bias, slope scale and slope clamp."""
    normal_offset: Length = field(default=Length(0.0, "world"),
                                  metadata={"doc": "move the lookup point along the normal"})
    depth_bias: Length = field(default=Length(0.0, "world"), metadata={"doc": "constant depth offset added to z1"})
    slope_scale: float = field(default=0.0, metadata={"doc": "factor on m, the caster's depth change per texel",
                                                       "min": 0.0})
    slope_clamp: Length = field(default=Length(math.inf, "world"),
                                metadata={"doc": "largest slope term (default: no clamp)", "min": 0.0})


def needs(params) -> frozenset:
    """The map layers this instance reads: ``slope`` only when its slope term is on."""
    return frozenset({"slope"}) if params.slope_scale > 0 else frozenset()


def shift(rx, p):
    """The receiver moved along its geometric normal by ``normal_offset`` (world units)."""
    return rx.moved(rx.p_world + rx.n_world * p.normal_offset)


def margin(rx, tap, p):
    """z1 + depth_bias + min(slope_clamp, slope_scale * m) - d' (view depth units; m from the slope layer)."""
    threshold = tap.z1 + p.depth_bias
    if tap.slope is not None:           # a map without the slope layer: no instance of it needs one
        threshold = threshold + dr.minimum(p.slope_clamp, p.slope_scale * tap.slope)
    return threshold - rx.depth
