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

from ..maps import lookup
from .. import prefilter
from ..prefilter.base import normalized_depth

KINDS = {kind.NAME: kind for kind in prefilter.REGISTRY}


def moments(kind: str, t, params) -> list:
    """The moments of normalized depth ``t`` (Dr.Jit, attached) as ``dsm.prefilter.<kind>.moments`` defines them."""
    if kind == "esm":
        # grad's own form, exp(c (t - 1)) = exp(c t) / exp(c): the kit's moment over a constant, so that a
        # ground texel's moment is near 1 and its gradient, 1 / moment, does not fall below float32's normal
        # range (at c = 80, 1 / exp(c t) ~ 1e-35 times a pixel's area is flushed to zero on the CPU)
        return [dr.exp(params.c * (t - 1.0))]
    return KINDS[kind].moments(t, params)      # vsm, msm: polynomials; evsm: its warps, numpy or Dr.Jit alike


def visibility(kind: str, b: list, t, params):
    """The kind's visibility of filtered moments ``b`` at the receiver's normalized depth ``t``: the kit's
    function (``dsm.prefilter.<kind>.visibility``, AD-safe: Chebyshev's derivative in its stable form,
    MSM's divisions guarded); ESM's with its moment's constant (above)."""
    if kind == "esm":
        return dr.clip(dr.exp(dr.log(b[0]) - params.c * (t - 1.0)), 0.0, 1.0)
    return KINDS[kind].visibility(b, t, params)


def depth01(z1, view):
    """The map's depth normalized to the view's range (the kit's ``normalized_depth``), attached."""
    return normalized_depth(z1, view)


def box_blur(x, width: int, R: int):
    """Separable box blur of odd ``width`` texels of a R x R map (flat mi.Float), clamped to the face.
    grad's own: in Dr.Jit so the blurred moments stay attached (the kit's, prefilter.base.separable_blur,
    runs in numpy float64, cut from the graph)."""
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


def bilinear(x, u, v, R: int):
    """Bilinear fetch of map ``x`` (flat, R x R) at map positions (u, v) in texels (clamped at the border),
    as a GPU samples a filtered moment map (the kit's runs fetch the nearest texel): the taps of
    :func:`dsm.maps.lookup.bilinear_taps`."""
    out = dr.zeros(mi.Float, dr.width(u))
    for uc, vc, w in lookup.bilinear_taps(u, v):
        ii, jj = dr.clip(mi.Int32(dr.floor(uc)), 0, R - 1), dr.clip(mi.Int32(dr.floor(vc)), 0, R - 1)
        out += w * dr.gather(mi.Float, x, mi.UInt32(jj * R + ii))
    return out
