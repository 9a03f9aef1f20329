"""Shadow maps ray-cast from the light through texel centres.

The first layer ``z1`` (depth of the first hit in the view's metric, the view's far bound
where a texel's ray hits nothing) and the shape of that hit, for attribution, are always
built. Extra attributes are built only when a scheme in the plan needs them:

- ``slope``: the caster's largest depth change per texel step, from the caster's plane at
  the texel (its geometric normal), as rasterizer depth bias computes it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

LAYERS = ("slope",)   # optional attributes a scheme may need (besides z1 and shape)


@dataclass
class ShadowMap:
    view: object
    z1: object                  # mi.Float, R*R, row-major (j * R + i)
    shape: object               # mi.UInt32, shape index of the first hit, 0xFFFFFFFF on a miss
    slope: object = None        # mi.Float or None
    rays: dict = field(default_factory=dict)   # rays cast, by kind

    @property
    def resolution(self) -> int:
        return self.view.resolution


def first_layer(scene, view):
    """(z1, shape index, preliminary hit, rays) for every texel of ``view``."""
    R = view.resolution
    rays = view.texel_rays(0, R * R)
    pi = scene.ray_intersect_preliminary(rays, coherent=True)
    valid = pi.is_valid()
    z1 = dr.select(valid, view.depth(rays.o) + pi.t * dr.dot(rays.d, view.ez), view.far)
    shape = dr.select(valid, pi.shape_index, 0xFFFFFFFF)
    return z1, shape, pi, rays


def caster_slope(view, pi, rays, z1):
    """m per texel: |depth change| to the next texel in u and in v on the caster's plane."""
    R = view.resolution
    si = pi.compute_surface_interaction(rays, ray_flags=mi.RayFlags.Minimal)
    idx = dr.arange(mi.UInt32, R * R)
    cu, cv = mi.Float(idx % view.R_u) + 0.5, mi.Float(idx // view.R_u) + 0.5
    du = dr.abs(view.depth_on_plane(cu + 1.0, cv, si.p, si.n) - z1)
    dv = dr.abs(view.depth_on_plane(cu, cv + 1.0, si.p, si.n) - z1)
    return dr.select(pi.is_valid(), dr.maximum(du, dv), 0.0)


def build(scene, view, needs) -> ShadowMap:
    """Build the layers ``needs`` asks for (a subset of LAYERS) over the whole map."""
    unknown = set(needs) - set(LAYERS)
    if unknown:
        raise ValueError(f"unknown map attributes {sorted(unknown)} (valid: {', '.join(LAYERS)})")
    z1, shape, pi, rays = first_layer(scene, view)
    slope = caster_slope(view, pi, rays, z1) if "slope" in needs else None
    R = view.resolution
    return ShadowMap(view, z1, shape, slope, rays={"map_first": R * R})


def arrays(smap: ShadowMap) -> tuple:
    return tuple(a for a in (smap.z1, smap.shape, smap.slope) if a is not None)
