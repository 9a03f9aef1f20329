"""Each technique's visibility per receiver, differentiable, through the kit's own lookups.

- ``nearest``, ``pcf_bilinear``: the kit's lookup (:func:`dsm.maps.lookup.visibility`) with a
  constant bias (Williams 1978) of ``bias`` world units. Nearest is a step of the depths and of the
  receiver's texel: its gradient is zero wherever it is defined. PCF's gradient comes through its
  bilinear weights (the receiver's map position: a light's parameters), never through a moving
  occluder, whose texels' tests only flip.
- ``pcss``: the kit's blocker search and penumbra estimate (:func:`dsm.maps.lookup.pcss_estimate`,
  Fernando 2005), then PCSS_FILTER^2 taps over the penumbra width, each a bilinear PCF (the kit's
  pcss reads nearest taps, whose gradient is zero): the width follows the blockers' attached depth.
- ``vsm``, ``esm``, ``evsm``, ``msm``: moments of the attached depth (:mod:`dsm.grad.moments`),
  blurred, fetched bilinearly, and the kind's own visibility.
- ``antialias``: the map's silhouette texels moved toward their neighbours (:mod:`dsm.grad.antialias`):
  the depth test's result per tap for the depth techniques, the moments for the moment techniques.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..core.types import Length
from ..maps import lookup
from ..schemes import constant
from . import antialias, moments


@dataclass
class Lookup:
    """What a technique reads: the attached map, the receivers, the edge weights (None: not built)."""
    amap: object
    rx: object
    edges: object
    bias: float


def _prm(look: Lookup):
    return lookup.resolve(constant.Params(bias=Length(look.bias, "world")), look.rx)


def _lit(look: Lookup, prm, u, v):
    """(depth test as 0/1, the tap) at the texel holding map position (u, v)."""
    tap = lookup.tap_at(look.rx, look.amap.smap, u, v)
    return dr.select(lookup.lit(constant, look.rx, tap, prm), 1.0, 0.0), tap


def lit_antialiased(look: Lookup, prm, u, v):
    """The depth test at (u, v)'s texel moved toward its neighbours' tests by the edge weights."""
    base, tap = _lit(look, prm, u, v)
    out = base
    for d in antialias.DIRECTIONS:
        other, _ = _lit(look, prm, tap.cu_map + d[0], tap.cv_map + d[1])
        out = out + dr.gather(mi.Float, look.edges.weights[d], tap.idx) * (other - base)
    return out


def _test(look: Lookup, prm, u, v, aa: bool):
    return lit_antialiased(look, prm, u, v) if aa else _lit(look, prm, u, v)[0]


def pcf(look: Lookup, prm, u, v, aa: bool):
    """Bilinear PCF at map positions (u, v): the four tests blended by the fractional position."""
    out = dr.zeros(mi.Float, dr.width(u))
    for uc, vc, w in lookup.bilinear_taps(u, v):       # a test at each texel's centre
        out += w * _test(look, prm, uc, vc, aa)
    return out


def pcss(look: Lookup, prm, aa: bool):
    """PCSS: the kit's penumbra estimate, then bilinear PCF taps over its width (1 without blockers)."""
    rx = look.rx
    _, width, found = lookup.pcss_estimate(constant, prm, rx, look.amap.smap)
    w = dr.clip(width, 1.0, lookup.PCSS_MAX_TEXELS)
    n = lookup.PCSS_FILTER
    offs = [(a + 0.5) / n - 0.5 for a in range(n)]
    vis = dr.zeros(mi.Float, dr.width(rx.u_map))
    for a in offs:
        for b in offs:
            vis += pcf(look, prm, rx.u_map + a * w, rx.v_map + b * w, aa) / (n * n)
    return dr.select(found, vis, 1.0)


def moment_visibility(look: Lookup, kind: str, blur: int, aa: bool):
    """A pre-filtered map's V: moments of the attached depth, (antialiased,) blurred, fetched bilinearly."""
    smap = look.amap.smap
    params = moments.KINDS[kind].Params()
    m = moments.moments(kind, moments.depth01(smap.z1, smap.view), params)
    if aa:
        m = antialias.mix(m, look.edges)
    R = smap.view.resolution
    b = [moments.bilinear(moments.box_blur(x, blur, R), look.rx.u_map, look.rx.v_map, R) for x in m]
    return moments.visibility(kind, b, moments.depth01(look.rx.depth, smap.view), params)


def visibility(look: Lookup, tech):
    """V per receiver (attached) of technique ``tech`` (a dsm.grad.spec.Technique)."""
    rx = look.rx
    if tech.name in moments.KINDS:
        return moment_visibility(look, tech.name, tech.blur, tech.antialias)
    prm = _prm(look)
    if tech.name == "nearest":
        if not tech.antialias:
            return lookup.visibility(constant, constant.Params(bias=Length(look.bias, "world")), rx,
                                     look.amap.smap, "nearest")[0]
        return lit_antialiased(look, prm, rx.u_map, rx.v_map)
    if tech.name == "pcf_bilinear":
        if not tech.antialias:
            return lookup.visibility(constant, constant.Params(bias=Length(look.bias, "world")), rx,
                                     look.amap.smap, "pcf_bilinear")[0]
        return pcf(look, prm, rx.u_map, rx.v_map, True)
    if tech.name == "pcss":
        return pcss(look, prm, tech.antialias)
    raise ValueError(f"unknown technique {tech.name!r}")
