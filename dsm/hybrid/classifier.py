"""AMD FidelityFX Shadow Classifier (FidelityFX SDK 1.x, MIT), re-derived from its documentation.

Sources: the SDK's docs/techniques/classifier.md (8x4 tiles; a blocker search in a Poisson disc
whose radius is the sun's size scaled by the receiver's light-space depth; pixels rejected where
the cascades' min/max depth decide lit or shadowed; the ray interval from the cascades), the API
page of ``FfxClassifierShadowDispatchDescription`` (the parameters' names) and the Hybrid Shadows
sample's page and UI defaults (docs/samples/hybrid-shadows.md: TileCutOff 0 to 32, "PCF offset"
0 to 0.008, "Sun Solid Angle" 0 to 1 degree).

Per receiver at light-space depth ``d`` (texel width ``w`` there):

- search radius ``r = sunSizeLightSpace * d`` (world), ``r / w + 1`` texels (grown by a texel,
  as AMD does); 24 taps of a Poisson disc (:data:`DISC`, drawn here, not AMD's table) at the
  receiver's map position; taps off the map's face are skipped (AMD's bounds check);
- ``c = d - blockerOffset`` (blockerOffset in the map's depth range, AMD's depth being [0, 1]);
  over the taps ``z``: ``maxD``, ``minD`` and the deepest blocker ``zb = max{z < c}`` (0 without one);
- shadowed when ``maxD <= c`` (every tap a blocker); lit when ``bRejectLitPixels`` and
  ``minD >= c`` (no blocker); otherwise flagged for a ray;
- an 8 x 4 tile of the camera image whose flagged receivers number ``tileCutOff`` or fewer is
  dropped (its receivers keep the map's answer);
- with ``bUseCascadesForRayT`` (directional lights only: their depth is distance along the ray),
  each ray spans ``[t_min, t_max]`` from the receiver, ``t_min = max(d - zb - blockerOffset, 0)``,
  ``t_max = sqrt((d - minD + blockerOffset)^2 + r^2)``, the least t_min and largest t_max of its
  tile's flagged receivers.

Where the kit departs: a receiver the classifier does not trace keeps the case's own answer (its
scheme, filter and format), not the blocker search's lit mask, so every scheme can be measured
with every rule; the kit's light stays hard (the sun's size is the classifier's parameter only,
V* is a point sun's) and the map is the kit's map for the view (one map, or its cascades).

Defaults are the sample's (FidelityFX-SDK samples/hybridshadows, ``HybridShadowsRenderModule``):
``tileCutOff = 0``, ``blockerOffset = 0.002``, ``bRejectLitPixels = true``,
``bUseCascadesForRayT = true``, and a sun of 0.25 degrees, whose ``sunSizeLightSpace`` for a light
view along the light is ``tan(0.5 * 0.25 degrees)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..maps import lookup
from .base import Inputs, Selection

NAME = "classifier"
SOURCE = "AMD FidelityFX Shadow Classifier (FidelityFX SDK, docs/techniques/classifier.md)"

TILE_W, TILE_H = 8, 4            # AMD's tile: one 32-lane wave
SUN_DEGREES = 0.25               # the Hybrid Shadows sample's sun ("Sun Solid Angle", degrees)
SUN_SIZE_DEFAULT = math.tan(0.5 * math.radians(SUN_DEGREES))


def poisson_disc(n: int = 24, seed: int = 69, candidates: int = 64) -> np.ndarray:
    """(n, 2) points in the unit disc by Mitchell's best candidate (each the farthest of
    ``candidates`` uniform draws from those before): a Poisson-disc-like set, fixed by ``seed``."""
    rng = np.random.default_rng(seed)
    pts = []
    while len(pts) < n:
        r, a = np.sqrt(rng.random(candidates)), 2 * np.pi * rng.random(candidates)
        cand = np.stack([r * np.cos(a), r * np.sin(a)], 1)
        if not pts:
            pts.append(cand[0])
            continue
        dist = np.min(np.linalg.norm(cand[:, None] - np.asarray(pts)[None], axis=2), axis=1)
        pts.append(cand[int(np.argmax(dist))])
    return np.asarray(pts)


DISC = poisson_disc()            # AMD's blocker search takes 24 taps (k_poissonDiscSampleCountHigh)


@dataclass(frozen=True)
class Params:
    """AMD's parameters, named as FfxClassifierShadowDispatchDescription names them."""
    sunSizeLightSpace: float = field(default=SUN_SIZE_DEFAULT, metadata={
        "doc": "classifier: the sun's size as lateral spread per unit of light-space depth (the sample's "
               "0.25 degree sun: tan 0.125 degrees)", "min": 0.0})
    tileCutOff: int = field(default=0, metadata={"doc": "classifier: an 8x4 tile with this many flagged "
                                                        "pixels or fewer is dropped", "min": 0, "max": 32})
    bRejectLitPixels: bool = field(default=True, metadata={"doc": "classifier: pixels whose search finds no "
                                                                  "blocker are lit, not traced"})
    blockerOffset: float = field(default=0.002, metadata={"doc": "classifier: depth offset of the blocker test, "
                                                                 "fraction of the map's depth range", "min": 0.0})
    bUseCascadesForRayT: bool = field(default=True, metadata={"doc": "classifier: rays shortened to the "
                                                                     "interval the map allows (directional)"})


def search(rx, smap, params) -> tuple:
    """Per receiver (Dr.Jit): (flagged, lit by the search, t_min, t_max) of the blocker search."""
    view = smap.view
    n = dr.width(rx.depth)
    d = rx.depth
    off = dr.opaque(mi.Float, params.blockerOffset) * dr.opaque(mi.Float, float(view.depth_range))
    radius_world = dr.opaque(mi.Float, params.sunSizeLightSpace) * d
    radius = radius_world / rx.texel_world + 1.0
    cmp = d - off
    max_d, min_d = dr.full(mi.Float, -dr.inf, n), dr.full(mi.Float, dr.inf, n)
    deepest = dr.zeros(mi.Float, n)
    size = mi.Float(view.R_u)
    for a, b in DISC:
        u, v = rx.u_map + float(a) * radius, rx.v_map + float(b) * radius
        on = (u >= 0) & (v >= 0) & (u < size) & (v < size)
        z = lookup.tap_at(rx, smap, u, v).z1
        max_d = dr.select(on, dr.maximum(max_d, z), max_d)
        min_d = dr.select(on, dr.minimum(min_d, z), min_d)
        deepest = dr.select(on & (z < cmp), dr.maximum(deepest, z), deepest)
    shadowed = max_d <= cmp
    lit = (min_d >= cmp) if params.bRejectLitPixels else dr.zeros(mi.Bool, n)
    t_min = dr.maximum(d - deepest - off, 0.0)
    t_max = dr.sqrt(dr.square(d - min_d + off) + dr.square(radius_world))
    return ~shadowed & ~lit, lit, t_min, t_max


def tiles(pixels: np.ndarray, width: int) -> np.ndarray:
    """The 8x4 tile of each pixel (row-major tiles over the image)."""
    x, y = pixels % width, pixels // width
    return (y // TILE_H) * ((width + TILE_W - 1) // TILE_W) + x // TILE_W


def select(inputs: Inputs, params) -> Selection:
    """The flagged receivers of the tiles kept, with their tile's ray interval where it applies."""
    if inputs.n == 0:
        return Selection(np.zeros(0, bool))
    flag, _, t_min, t_max = search(inputs.rx, inputs.smap, params)
    flag = flag.numpy().astype(bool)
    tile = tiles(inputs.pixels.astype(np.int64), inputs.width)
    count = np.bincount(tile[flag], minlength=int(tile.max()) + 1)
    trace = flag & (count[tile] > params.tileCutOff)
    if not (params.bUseCascadesForRayT and inputs.directional):
        return Selection(trace)
    lo, hi = np.full(count.size, np.inf, np.float32), np.zeros(count.size, np.float32)
    np.minimum.at(lo, tile[trace], t_min.numpy()[trace])
    np.maximum.at(hi, tile[trace], t_max.numpy()[trace])
    return Selection(trace, lo[tile], hi[tile])
