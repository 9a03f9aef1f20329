"""Exponential shadow maps (Annen, Mertens, Seidel, Flerackers & Kautz, "Exponential Shadow
Maps", Graphics Interface 2008).

One moment, E[exp(c t)]. The depth test is approximated by exp(-c (t_r - z)), exact for a
planar occluder in front of the receiver as c grows: V = clamp(exp(-c t_r) E[exp(c z)], 0, 1),
evaluated as exp(log E - c t_r) so that neither factor under- or overflows float32. The
exponent ``c`` trades leaking (small c lights receivers close behind an occluder) against
overflow: exp(c) must fit the format (c <= 88.72 in float32; c <= 11.09 in float16; a config beyond is refused).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import numpy as np

NAME = "esm"
SOURCE = "Annen et al. 2008 (Graphics Interface), Exponential Shadow Maps"
encode = decode = None      # stored as floats only (base.FLOAT_FORMATS)


@dataclass(frozen=True)
class Params:
    """ESM's exponent c (per normalized depth)."""
    c: float = field(default=80.0, metadata={"min": 1.0, "tune": ("linear", 1.0, 88.0, "moments")})


def count(params) -> int:
    """One moment: E[exp(c t)]."""
    return 1


def moment_key(params) -> tuple:
    """The moment depends on the exponent."""
    return (params.c,)


def log_max(params) -> float:
    """The largest natural log of a stored moment: c (at t = 1)."""
    return params.c


def moments(t, params) -> list:
    """[exp(c t)] per texel."""
    return [np.exp(params.c * t)]


def visibility(b, t, prm):
    """clamp(exp(log E[exp(c z)] - c t), 0, 1)."""
    return dr.clip(dr.exp(dr.log(b[0]) - prm.c * t), 0.0, 1.0)
