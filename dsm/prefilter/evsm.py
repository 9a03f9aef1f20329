"""Exponential variance shadow maps (Lauritzen & McCool, "Layered Variance Shadow Maps",
Graphics Interface 2008, section 4: exponential warping).

The depth, remapped to x = 2 t - 1 in [-1, 1], is warped by exp(c+ x) and by -exp(-c- x) (both
increasing in x); Chebyshev's bound (:func:`dsm.prefilter.base.chebyshev`) is taken in each warped
space and V is the smaller. ``moments = 2`` keeps the positive warp only (E[p], E[p^2]);
``moments = 4`` both (E[p], E[p^2], E[n], E[n^2]). The minimum variance is given in normalized
depth and carried into each warped space by the warp's slope at the receiver:
var_min = min_variance (dw/dt)^2, dw/dt = 2 c exp(+-c x) (a first-order change of variables).
Then the light-bleeding reduction linstep(bleed, 1, V) as for VSM. exp(2 c+) must fit the
format: c <= 44.36 in float32, c <= 5.54 in float16 (a config beyond is refused).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from .base import chebyshev, linstep

NAME = "evsm"
SOURCE = "Lauritzen & McCool 2008 (Graphics Interface), Layered Variance Shadow Maps, exponential warp"
encode = decode = None      # stored as floats only (base.FLOAT_FORMATS)
MOMENT_COUNTS = (2, 4)


@dataclass(frozen=True)
class Params:
    """EVSM's positive and negative exponents, moments (2 or 4), minimum variance and bleed reduction."""
    positive: float = field(default=40.0, metadata={"min": 0.5, "tune": ("linear", 0.5, 44.0, "moments")})
    negative: float = field(default=5.0, metadata={"min": 0.5, "tune": ("linear", 0.5, 44.0, "moments"),
                                                   "read_when": ("moments", 4)})
    moments: int = field(default=4, metadata={"choices": MOMENT_COUNTS})
    min_variance: float = field(default=1e-4, metadata={"min": 0.0, "tune": ("log", 1e-12, 0.1)})
    bleed: float = field(default=0.0, metadata={"min": 0.0, "max": 0.999, "tune": ("linear", 0.0, 0.9)})


def count(params) -> int:
    """2 or 4 moments, as ``params.moments`` says."""
    return params.moments


def moment_key(params) -> tuple:
    """The moments depend on the exponents and their count."""
    return (params.positive, params.negative, params.moments)


def log_max(params) -> float:
    """The largest natural log of a stored moment: 2 c of E[p^2] or E[n^2] at x = +-1."""
    return 2.0 * max(params.positive, params.negative if params.moments == 4 else 0.0)


def warp(t, c: float):
    """exp(c x), x = 2 t - 1, of normalized depths ``t`` (numpy or Dr.Jit: the build's moments, the
    lookup and dsm grad's attached moments warp alike); p = warp(t, c+), n = -warp(t, -c-)."""
    exp = dr.exp if dr.is_array_v(t) else np.exp
    return exp(c * (2.0 * t - 1.0))


def moments(t, params) -> list:
    """[p, p^2] or [p, p^2, n, n^2] of the warps (numpy float64, or Dr.Jit)."""
    p = warp(t, params.positive)
    if params.moments != 4:
        return [p, p * p]
    n = -warp(t, -params.negative)
    return [p, p * p, n, n * n]


def visibility(b, t, prm):
    """The smaller warped Chebyshev bound (one bound with 2 moments), bleed-reduced."""
    p = warp(t, prm.positive)
    slope_p = 2.0 * prm.positive * p
    v = chebyshev(b[0], b[1], p, prm.min_variance * slope_p * slope_p)
    if len(b) == 4:
        n = -warp(t, -prm.negative)
        slope_n = 2.0 * prm.negative * n
        v = dr.minimum(v, chebyshev(b[2], b[3], n, prm.min_variance * slope_n * slope_n))
    return linstep(prm.bleed, 1.0, v)
