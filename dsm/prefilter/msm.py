"""Moment shadow maps, Hamburger 4MSM (Peters & Klein, "Moment Shadow Mapping", I3D 2015,
algorithm 2).

Moments b = E[t], E[t^2], E[t^3], E[t^4] of the normalized depth. The moment bias pulls them
toward the point (0.5, 0.5, 0.5, 0.5) of a harmless distribution, b' = (1 - a) b + a (0.5, ...),
as Peters' reference code does for depth in [0, 1] (it keeps the Hankel matrix invertible
against rounding and the storage's quantization). Then, with the receiver at t: solve
B c = (1, t, t^2) for the 3 x 3 Hankel matrix B of (1, b1', b2'; b1', b2', b3'; b2', b3', b4')
(Cholesky, as the paper's code), take the roots z2 <= z3 of c0 + c1 z + c2 z^2, and sum the
weights of the three-point distribution at (t, z2, z3) that lie in front of the receiver: the
sharpest lower bound on the shadow the four moments allow (Hamburger's moment problem).
V = 1 - that bound, clamped to [0, 1]. Where float32 leaves B singular (the bound is NaN: a
window of one depth under a small bias), Chebyshev's bound of the biased E[t], E[t^2] stands in.

``format = "unorm16"`` is the paper's optimized moment quantization (its section "Optimized
Moment Quantization"): the power moments go through a fixed affine map, q = b Theta + (0.0359558848,
0, 0, 0) (b a row vector), whose image of the moments of depths in [0, 1] lies in [0, 1] and
spreads the four nearly collinear moments over the unit cube, then each q is stored as k / 65535
(:func:`dsm.prefilter.base.stored`); the lookup maps the filtered q back, b = (q - offset)
Theta^-1, before the bound (:func:`decode`). The constants are those of the paper's code as MJP's
Shadows sample ships it (github.com/TheRealMJP/Shadows, ``Shadows/MSM.hlsl``, commit 37b61461,
``GetOptimizedMoments``; Unity's HDRP ``ShadowMoments.hlsl`` ``ShadowMoments_Encode16MSM`` holds
the same); Theta^-1 is the float64 inverse of that Theta, which agrees with the published
``ConvertOptimizedMoments`` to its 10 printed digits (a test holds both). ``float16`` stores the
raw power moments as halves.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from .base import chebyshev, safe_div

NAME = "msm"
SOURCE = "Peters & Klein 2015 (I3D), Moment Shadow Mapping, algorithm 2 (Hamburger 4MSM)"
# Theta of the optimized 16-bit quantization, row i the coefficients of b_(i+1) in q_1 .. q_4
# (HLSL's mul(moments, float4x4(...)) in Shadows/MSM.hlsl, GetOptimizedMoments), and the offset of q
QUANTIZATION_MATRIX = np.array([[-2.07224649, 13.7948857237, 0.105877704, 9.7924062118],
                                [32.23703778, -59.4683975703, -1.9077466311, -33.7652110555],
                                [-68.571074599, 82.0359750338, 9.3496555107, 47.9456096605],
                                [39.3703274134, -35.364903257, -6.6543490743, -23.9728048165]])
QUANTIZATION_OFFSET = np.array([0.035955884801, 0.0, 0.0, 0.0])
# the exact float64 inverse (the published ConvertOptimizedMoments is it to ~1e-10)
DEQUANTIZATION_MATRIX = np.linalg.inv(QUANTIZATION_MATRIX)


@dataclass(frozen=True)
class Params:
    """MSM's moment bias a in [0, 1): b' = (1 - a) b + a (0.5, 0.5, 0.5, 0.5), and its depth bias
    (normalized depth subtracted from the receiver's, as the reference code's ``depthBias``)."""
    moment_bias: float = field(default=3e-5, metadata={"min": 0.0, "max": 0.999, "tune": ("log", 1e-8, 0.1)})
    depth_bias: float = field(default=0.0, metadata={"min": 0.0, "tune": ("linear", 0.0, 0.1)})


def count(params) -> int:
    """Four moments: E[t] .. E[t^4]."""
    return 4


def moment_key(params) -> tuple:
    """The moments do not depend on the bias (it is applied at lookup)."""
    return ()


def log_max(params) -> None:
    """None: no exponential moment, nothing a format could overflow."""
    return None


def moments(t, params) -> list:
    """[t, t^2, t^3, t^4] per texel."""
    t2 = t * t
    return [t, t2, t2 * t, t2 * t2]


def encode(t, params) -> list:
    """The optimized moments q = b(t) Theta + offset per texel (numpy float64; in [0, 1] for t in
    [0, 1]), each by Horner's rule in t: the four power moments are never held beside them (the
    build's peak stays that of the float formats' moments, plus the rounding's temporaries)."""
    out = []
    for j in range(4):
        c = QUANTIZATION_MATRIX[:, j]
        out.append(QUANTIZATION_OFFSET[j] + t * (c[0] + t * (c[1] + t * (c[2] + t * c[3]))))
    return out


def decode(q) -> list:
    """The power moments b = (q - offset) Theta^-1 of optimized moments ``q`` (numpy or Dr.Jit,
    one array per component; the lookup runs it in float32, as a shader would)."""
    d = [qi - float(o) for qi, o in zip(q, QUANTIZATION_OFFSET)]
    return [sum(float(DEQUANTIZATION_MATRIX[i, j]) * d[i] for i in range(4)) for j in range(4)]


def visibility(b, t, prm):
    """1 - the Hamburger 4MSM shadow bound at the receiver's normalized depth ``t``, its square root
    and divisions guarded (safe_div) so that a differentiated lookup (dsm grad) has no NaN from a
    branch it does not take: the same values as the unguarded algorithm wherever those are finite."""
    a = prm.moment_bias
    t = t - prm.depth_bias
    b0, b1, b2, b3 = ((1.0 - a) * m + a * 0.5 for m in b)
    # Cholesky of B, the non-trivial entries only (Peters & Klein 2015, supplement code)
    l32d22 = b2 - b0 * b1
    d22 = -b0 * b0 + b1
    sq_var = -b1 * b1 + b3
    d33d22 = sq_var * d22 - l32d22 * l32d22
    # float32 can leave the system singular (c2 = 0 for a window of one depth under a small bias);
    # Chebyshev's bound of the same biased moments, looser but defined, stands in there
    ok = (d22 != 0) & (d33d22 != 0)
    inv_d22 = safe_div(1.0, d22, ok)
    l32 = l32d22 * inv_d22
    c1 = t - b0
    c2 = t * t - b1 - l32 * c1
    c1 = c1 * inv_d22
    c2 = safe_div(c2 * d22, d33d22, ok)
    c1 = c1 - l32 * c2
    c0 = 1.0 - (c1 * b0 + c2 * b1)
    ok &= c2 != 0
    p, q = safe_div(c1, c2, ok), safe_div(c0, c2, ok)
    r2 = p * p * 0.25 - q
    r = dr.select(r2 > 0, dr.sqrt(dr.select(r2 > 0, r2, 1.0)), 0.0)
    z2, z3 = -p * 0.5 - r, -p * 0.5 + r
    beyond, between = z3 < t, z2 < t
    s0 = dr.select(beyond, z2, t)
    s1 = dr.select(beyond, t, z2)
    s2 = dr.select(beyond, 1.0, 0.0)
    den = (z3 - s1) * (t - z2)
    quotient = safe_div(s0 * z3 - b0 * (s0 + z3) + b1, den, between & (den != 0))   # 0 where no root lies in front
    v = 1.0 - dr.clip(s2 + quotient, 0.0, 1.0)
    return dr.select(ok & dr.isfinite(v), v, chebyshev(b0, b1, t, 0.0))
