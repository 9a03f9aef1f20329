"""Moment maps in Dr.Jit: the kinds' moments of z1, the box blur and a bilinear fetch, all attached.

The kit's pre-filtered maps (:mod:`dsm.prefilter`) compute moments and blur in numpy float64
(exact, and cut from the graph) and fetch the nearest texel. Here the same moments (each kind's
definition, ``dsm.prefilter.<kind>``) are computed in Dr.Jit from the attached depth, blurred by
the same separable box of odd width W (clamped to the face), and fetched bilinearly, as a GPU
samples a filtered moment map: a nearest fetch has no gradient in the receiver's map position.
The visibility is the kind's own ``visibility`` (Chebyshev, ESM's exponential, EVSM's warped
bound, MSM's Hamburger bound).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..prefilter import esm, evsm, msm, vsm
from ..prefilter.base import chebyshev, linstep, normalized_depth

KINDS = {"vsm": vsm, "esm": esm, "evsm": evsm, "msm": msm}


def moments(kind: str, t, params) -> list:
    """The moments of normalized depth ``t`` (Dr.Jit, attached) as ``dsm.prefilter.<kind>.moments`` defines them."""
    if kind == "esm":
        # exp(c (t - 1)) = exp(c t) / exp(c): the kit's moment over a constant, so that a ground texel's
        # moment is near 1 and its gradient, 1 / moment, does not fall below float32's normal range
        # (at c = 80, 1 / exp(c t) ~ 1e-35 times a pixel's area is flushed to zero on the CPU)
        return [dr.exp(params.c * (t - 1.0))]
    if kind == "evsm":
        p, n = _evsm_warps(t, params)
        return [p, p * p] + ([n, n * n] if params.moments == 4 else [])
    return KINDS[kind].moments(t, params)      # vsm, msm: polynomials, Dr.Jit as well as numpy


def _evsm_warps(t, params):
    """EVSM's warps as the kit computes them: p = exp(c+ x), n = -exp(-c- x), x = 2t - 1."""
    x = 2.0 * t - 1.0
    return dr.exp(params.positive * x), -dr.exp(-params.negative * x)


def chebyshev_stable(mean, mean_sq, t, min_variance):
    """Chebyshev's bound as the kit's (dsm.prefilter.base.chebyshev), written 1 / (1 + (d / sigma)^2):
    the same value, while the kit's var / (var + d^2) squares EVSM's variance (up to e^80) in its
    derivative, beyond float32."""
    var = dr.maximum(mean_sq - mean * mean, min_variance)
    has = var > 0
    sigma = dr.sqrt(dr.select(has, var, 1.0))
    r = _safe_div(t - mean, sigma, has)
    bound = dr.select(has, 1.0 / (1.0 + r * r), 0.0)
    return dr.select(t <= mean, 1.0, bound)


def _evsm_visibility(b, t, prm):
    """The kit's EVSM visibility (dsm.prefilter.evsm.visibility) with the stable form of the bound."""
    p, n = _evsm_warps(t, prm)
    slope_p = 2.0 * prm.positive * p
    v = chebyshev_stable(b[0], b[1], p, prm.min_variance * slope_p * slope_p)
    if len(b) == 4:
        slope_n = 2.0 * prm.negative * n
        v = dr.minimum(v, chebyshev_stable(b[2], b[3], n, prm.min_variance * slope_n * slope_n))
    return linstep(prm.bleed, 1.0, v)


def _safe_div(num, den, use):
    """num / den where ``use``; elsewhere a finite stand-in whose gradient is 0 (a select's unused
    branch still back-propagates 0 * inf = NaN through an unguarded division or square root)."""
    return dr.select(use, num / dr.select(use, den, 1.0), 0.0)


def _msm_visibility(b, t, prm):
    """The kit's Hamburger 4MSM visibility (dsm.prefilter.msm.visibility, Peters & Klein 2015,
    algorithm 2), step for step, with its square root and divisions guarded for AD: the same values
    where the kit's are finite (tests/test_grad.py holds both)."""
    a = prm.moment_bias
    t = t - prm.depth_bias
    b0, b1, b2, b3 = ((1.0 - a) * m + a * 0.5 for m in b)
    l32d22 = b2 - b0 * b1
    d22 = -b0 * b0 + b1
    sq_var = -b1 * b1 + b3
    d33d22 = sq_var * d22 - l32d22 * l32d22
    ok = (d22 != 0) & (d33d22 != 0)
    inv_d22 = _safe_div(1.0, d22, ok)
    l32 = l32d22 * inv_d22
    c1 = t - b0
    c2 = t * t - b1 - l32 * c1
    c1 = c1 * inv_d22
    c2 = _safe_div(c2 * d22, d33d22, ok)
    c1 = c1 - l32 * c2
    c0 = 1.0 - (c1 * b0 + c2 * b1)
    ok &= c2 != 0
    p, q = _safe_div(c1, c2, ok), _safe_div(c0, c2, ok)
    r2 = p * p * 0.25 - q
    r = dr.select(r2 > 0, dr.sqrt(dr.select(r2 > 0, r2, 1.0)), 0.0)
    z2, z3 = -p * 0.5 - r, -p * 0.5 + r
    beyond, between = z3 < t, z2 < t
    s0 = dr.select(beyond, z2, t)
    s1 = dr.select(beyond, t, z2)
    s2 = dr.select(beyond, 1.0, 0.0)
    den = (z3 - s1) * (t - z2)
    quotient = _safe_div(s0 * z3 - b0 * (s0 + z3) + b1, den, between & (den != 0))
    v = 1.0 - dr.clip(s2 + quotient, 0.0, 1.0)
    return dr.select(ok & dr.isfinite(v), v, chebyshev(b0, b1, t, 0.0))


def visibility(kind: str, b: list, t, params):
    """The kind's visibility of filtered moments ``b`` at the receiver's normalized depth ``t``: the kit's
    function (``dsm.prefilter.<kind>.visibility``); ESM's with its moment's constant, EVSM's with
    the stable form of Chebyshev's bound, MSM's guarded for AD."""
    if kind == "esm":
        return dr.clip(dr.exp(dr.log(b[0]) - params.c * (t - 1.0)), 0.0, 1.0)
    if kind == "evsm":
        return _evsm_visibility(b, t, params)
    if kind == "msm":
        return _msm_visibility(b, t, params)
    return KINDS[kind].visibility(b, t, params)


def depth01(z1, view):
    """The map's depth normalized to the view's range (the kit's ``normalized_depth``), attached."""
    return normalized_depth(z1, view)


def box_blur(x, width: int, R: int):
    """Separable box blur of odd ``width`` texels of a R x R map (flat mi.Float), clamped to the face."""
    if width <= 1:
        return x
    idx = dr.arange(mi.UInt32, R * R)
    i, j = mi.Int32(idx % R), mi.Int32(idx // R)
    r = width // 2
    for axis in (0, 1):
        acc = dr.zeros(mi.Float, R * R)
        for k in range(-r, r + 1):
            ii = dr.clip(i + (k if axis == 0 else 0), 0, R - 1)
            jj = dr.clip(j + (k if axis == 1 else 0), 0, R - 1)
            acc += dr.gather(mi.Float, x, mi.UInt32(jj * R + ii))
        x = acc / width
    return x


def bilinear_taps(u, v):
    """The four texels around map positions (u, v) in texels: (weight, i, j) with (i, j) a texel's
    integer index (float, unclamped) and the weights bilinear in the fractional position."""
    fx, fy = u - 0.5, v - 0.5
    i0, j0 = dr.floor(fx), dr.floor(fy)
    wx, wy = fx - i0, fy - j0
    for a in (0, 1):
        for b in (0, 1):
            yield (wx if a else 1.0 - wx) * (wy if b else 1.0 - wy), i0 + a, j0 + b


def bilinear(x, u, v, R: int):
    """Bilinear fetch of map ``x`` (flat, R x R) at map positions (u, v) in texels (clamped at the border)."""
    out = dr.zeros(mi.Float, dr.width(u))
    for w, i, j in bilinear_taps(u, v):
        ii, jj = dr.clip(mi.Int32(i), 0, R - 1), dr.clip(mi.Int32(j), 0, R - 1)
        out += w * dr.gather(mi.Float, x, mi.UInt32(jj * R + ii))
    return out
