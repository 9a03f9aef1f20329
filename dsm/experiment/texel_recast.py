"""A map's texels re-cast where casters moved (cache policy ``invalidate``): which, and the map composed.

A texel of a map holds what its one ray through the texel's centre met (its first hit, slope and
second depth), so a texel whose ray meets no moved caster's bounds, neither where the caster was
nor where it is, holds the same values in a fresh cast: those are kept, the others taken from
this frame's cast. The test is a float64 slab test (numpy) of the float32 rays as cast against
bounds grown by a margin that holds the float32 rounding of the casters' vertices and of the
intersection test (a few float32 steps at the coordinates' magnitude), so it only ever re-casts
too many texels, never too few."""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline

F32_STEPS = 8.0 * 2.0 ** -24    # the bounds' margin: this many float32 units at the coordinates' magnitude ...
RELATIVE = 1e-6                 # ... plus this fraction of the bounds' diagonal


def touched(view, boxes) -> np.ndarray:
    """Per texel of ``view`` (its storage order), whether its ray (t >= 0) meets any of ``boxes`` [(lo, hi)]."""
    ray = view.texel_rays(0, view.n_texels)
    o, d = pipeline.points_np(ray.o), pipeline.points_np(ray.d)
    out = np.zeros(len(o), bool)
    for lo, hi in boxes:
        scale = max(np.abs(o).max(), np.abs(lo).max(), np.abs(hi).max())
        g = F32_STEPS * scale + RELATIVE * np.linalg.norm(np.subtract(hi, lo))
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - g - o) / d, (hi + g - o) / d
        inside = (o >= lo - g) & (o <= hi + g)                 # a ray parallel to a slab: inside it or never
        t1 = np.where(d == 0, np.where(inside, -np.inf, np.inf), t1)
        t2 = np.where(d == 0, np.where(inside, np.inf, -np.inf), t2)
        near, far = np.minimum(t1, t2).max(1), np.maximum(t1, t2).min(1)
        out |= (far >= near) & (far >= 0)
    return out


def compose(kept, fresh, mask: np.ndarray):
    """The map ``kept`` with the texels of ``mask`` taken from ``fresh`` (same view and layers)."""
    m = mi.Bool(mask)
    pick = lambda a, b: None if a is None else dr.select(m, b, a)
    out = dataclasses.replace(kept, view=fresh.view, z1=pick(kept.z1, fresh.z1), shape=pick(kept.shape, fresh.shape),
                              slope=pick(kept.slope, fresh.slope), z2=pick(kept.z2, fresh.z2))
    dr.eval(out.z1, out.shape)
    return out
