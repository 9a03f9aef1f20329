"""Exact visibility V* of each receiver from a light, by shadow rays (once per scene/light).

Rays leave the receiver just beyond a bound on its hit point's floating-point error
(:mod:`dsm.scenes.spawn`: a few float32 ulps of the coordinates and of the triangle the hit was
interpolated from, pbrt-v4's approach), toward the side the ray leaves by; a ray to a point
light stops that far short of it. The offset never grows with a hand-set constant times the
distance from the origin, so a scene moved far from the origin keeps its exact visibility as
long as float32 still resolves its gaps (see :mod:`dsm.scenes.spawn` for the limit).
``mitsuba_spawn=True`` uses Mitsuba's own ``spawn_ray`` / ``spawn_ray_to`` instead (for
comparison in tests).

The distance to the first occluder is kept: it tells peter-panning at a contact from a leak
far away.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import lights
from ..scenes import spawn


def shadow_rays(si, light, magnitude: float = 1.0, mitsuba_spawn: bool = False):
    """Rays from the receivers' surface interactions toward ``light`` (a LightSpec).

    ``magnitude``: the scene's largest coordinate, the extent used in the error bound of
    non-triangle shapes (a triangle's own extent is used for meshes).
    """
    n = dr.width(si.p)
    if not lights.get(light.type).POSITIONAL:      # a direction: the rays go against it
        d = dr.zeros(mi.Vector3f, n) - mi.Vector3f(*map(float, np.asarray(light.direction) /
                                                        np.linalg.norm(light.direction)))
        if mitsuba_spawn:
            return si.spawn_ray(d)
        return spawn.ray_along(si, si.n, d, hit_error(si, magnitude))
    target = mi.Point3f(*map(float, light.position))
    if mitsuba_spawn:
        return si.spawn_ray_to(target)
    return spawn.ray_to(si, si.n, target, hit_error(si, magnitude))


def hit_error(si, magnitude: float):
    """The spawn offset of each receiver (:func:`dsm.scenes.spawn.error_bound`)."""
    return spawn.error_bound(si, dr.opaque(mi.Float, float(magnitude)))


def visibility(scene, si, light, magnitude: float = 1.0, mitsuba_spawn: bool = False):
    """(V* as Bool, distance to the first occluder as Float, +inf where unoccluded)."""
    ray = shadow_rays(si, light, magnitude, mitsuba_spawn)
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    hit = pi.is_valid()
    return ~hit, dr.select(hit, pi.t, dr.inf)


def scene_magnitude(bbox) -> float:
    """The largest absolute coordinate of the scene's bounding box."""
    return float(np.max(np.abs(np.concatenate(bbox))))
