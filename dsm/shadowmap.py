"""Shadow maps ray-cast from the light through texel centres.

The first layer ``z1`` (depth of the first hit in the view's metric, the view's far bound
where a texel's ray hits nothing) and the shape of that hit, for attribution, are always
built. Extra attributes are built only when a scheme in the plan needs them:

- ``slope``: the caster's largest depth change per texel step, from the caster's plane at
  the texel (its geometric normal), as rasterizer depth bias computes it.
- ``z2``: the second surface along the texel's ray, found by spawning past the first hit
  with Mitsuba's own offset (``spawn_ray``); the view's far bound where there is none.

Culling is a property of the build, per shape (``CULL_NONE``, ``CULL_BACK``, ``CULL_FRONT``):
a culled hit is stepped over and the ray goes on. A face is a back face when its winding
normal points along the ray (away from the light).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

LAYERS = ("slope", "z2")   # optional attributes a scheme may need (besides z1 and shape)
CULL_NONE, CULL_BACK, CULL_FRONT = 0, 1, 2
CULLINGS = ("none", "back", "front", "back_closed")   # the choices of midpoint and dual
MAX_STEPS = 64             # surfaces stepped over per texel before giving up (reported, never silent)


@dataclass
class ShadowMap:
    view: object
    z1: object                  # mi.Float, faces*R*R, (face * R + j) * R + i
    shape: object               # mi.UInt32, shape index of the first hit, 0xFFFFFFFF on a miss
    slope: object = None        # mi.Float or None
    z2: object = None           # mi.Float or None
    culling: str = "none"
    unfinished: int = 0         # texels still searching after MAX_STEPS (0 in every sane scene)
    rays: dict = field(default_factory=dict)   # rays cast, by kind

    @property
    def resolution(self) -> int:
        return self.view.resolution


def first_layer(scene, view):
    """(z1, shape index, preliminary hit, rays) for every texel of ``view``."""
    rays = view.texel_rays(0, view.n_texels)
    pi = scene.ray_intersect_preliminary(rays, coherent=True)
    valid = pi.is_valid()
    z1 = dr.select(valid, view.ray_depth(rays.o, rays.d, pi.t), view.far)
    shape = dr.select(valid, pi.shape_index, 0xFFFFFFFF)
    return z1, shape, pi, rays


def plane_slope(view, p, n, z1, valid):
    """m per texel: |depth change| to the next texel in u and in v on the caster's plane (p, n)."""
    face, cu, cv = view.texel_coords(dr.arange(mi.UInt32, view.n_texels))
    du = dr.abs(view.depth_on_plane(cu + 1.0, cv, p, n, face) - z1)
    dv = dr.abs(view.depth_on_plane(cu, cv + 1.0, p, n, face) - z1)
    return dr.select(valid, dr.maximum(du, dv), 0.0)


def _count(mask) -> int:
    return int(dr.count(mask).numpy().ravel()[0])


def layered(scene, view, cull_modes: np.ndarray, want_z2: bool, want_slope: bool):
    """First (and second) accepted surface per texel under per-shape culling.

    Returns (z1, shape1, slope or None, z2 or None, rays by kind, unfinished texels).
    """
    n = view.n_texels
    ray = view.texel_rays(0, n)
    modes = mi.UInt32(np.asarray(cull_modes, np.uint32))
    need = 2 if want_z2 else 1
    z1 = dr.full(mi.Float, view.far, n)
    z2 = dr.full(mi.Float, view.far, n)
    shape1 = dr.full(mi.UInt32, 0xFFFFFFFF, n)
    p1, n1 = dr.zeros(mi.Point3f, n), dr.zeros(mi.Vector3f, n)
    found = dr.zeros(mi.UInt32, n)
    active = dr.full(mi.Bool, True, n)
    cast1, cast2 = dr.zeros(mi.UInt32, n), dr.zeros(mi.UInt32, n)   # rays cast per texel, by layer sought
    for _ in range(MAX_STEPS):
        cast1 += dr.select(active & (found == 0), 1, 0)
        cast2 += dr.select(active & (found == 1), 1, 0)
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        valid = active & pi.is_valid()
        si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.Minimal, active=valid)
        mode = dr.gather(mi.UInt32, modes, pi.shape_index, valid)
        back = dr.dot(si.n, ray.d) > 0
        culled = ((mode == CULL_BACK) & back) | ((mode == CULL_FRONT) & ~back)
        accept = valid & ~culled
        depth = view.depth(si.p)
        first, second = accept & (found == 0), accept & (found == 1)
        z1 = dr.select(first, depth, z1)
        shape1 = dr.select(first, pi.shape_index, shape1)
        if want_slope:
            p1 = dr.select(first, si.p, p1)
            n1 = dr.select(first, si.n, n1)
        z2 = dr.select(second, depth, z2)
        found += dr.select(accept, 1, 0)
        active = valid & (found < need)
        ray = dr.select(active, si.spawn_ray(ray.d), ray)
        dr.eval(z1, z2, shape1, p1, n1, found, active, ray, cast1, cast2)
        if _count(active) == 0:          # the one synchronisation per step
            break
    rays = {"map_first": int(dr.sum(cast1).numpy().ravel()[0]), "map_second": int(dr.sum(cast2).numpy().ravel()[0])}
    slope = plane_slope(view, p1, n1, z1, found > 0) if want_slope else None
    return z1, shape1, slope, (z2 if want_z2 else None), rays, _count(active)


def build(scene, view, needs, culling: str = "none", cull_modes=None) -> ShadowMap:
    """Build the layers ``needs`` asks for (a subset of LAYERS) over the whole map.

    ``cull_modes``: one of CULL_* per shape of the scene (index of scene.shapes()); ``culling``
    names the choice for the report. Without culling or a second layer, one ray per texel.
    """
    unknown = set(needs) - set(LAYERS)
    if unknown:
        raise ValueError(f"unknown map attributes {sorted(unknown)} (valid: {', '.join(LAYERS)})")
    culls = cull_modes is not None and np.any(np.asarray(cull_modes) != CULL_NONE)
    if not culls and "z2" not in needs:
        z1, shape, pi, rays = first_layer(scene, view)
        slope = None
        if "slope" in needs:
            si = pi.compute_surface_interaction(rays, ray_flags=mi.RayFlags.Minimal)
            slope = plane_slope(view, si.p, si.n, z1, pi.is_valid())
        return ShadowMap(view, z1, shape, slope, rays={"map_first": view.n_texels}, culling=culling)
    modes = cull_modes if cull_modes is not None else np.zeros(len(scene.shapes()), np.uint32)
    z1, shape, slope, z2, rays, unfinished = layered(scene, view, modes, "z2" in needs, "slope" in needs)
    return ShadowMap(view, z1, shape, slope, rays=rays, z2=z2, culling=culling, unfinished=unfinished)


def cull_modes_for(culling: str, closed: list) -> np.ndarray:
    """Per-shape CULL_* for a culling choice, given each shape's closedness."""
    table = {"none": (CULL_NONE, CULL_NONE), "back": (CULL_BACK, CULL_BACK), "front": (CULL_FRONT, CULL_FRONT),
             "back_closed": (CULL_BACK, CULL_NONE), "front_closed": (CULL_FRONT, CULL_NONE)}
    if culling not in table:
        raise ValueError(f"unknown culling {culling!r} (valid: {', '.join(table)})")
    on_closed, on_open = table[culling]
    return np.array([on_closed if c else on_open for c in closed], np.uint32)


def arrays(smap: ShadowMap) -> tuple:
    return tuple(a for a in (smap.z1, smap.shape, smap.slope, smap.z2) if a is not None)
