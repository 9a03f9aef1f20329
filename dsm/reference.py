"""Exact visibility V* of each receiver from a light, by shadow rays (once per scene/light).

Rays leave the receiver with Mitsuba's robust spawn (``spawn_ray`` toward a directional
light, ``spawn_ray_to`` a spot's position), never a hand-tuned epsilon. The distance to the
first occluder is kept: it tells peter-panning at a contact from a leak far away.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def shadow_rays(si, light):
    """Rays from the receivers' surface interactions toward ``light`` (a LightSpec)."""
    if light.type == "directional":
        d = -mi.Vector3f(*map(float, np.asarray(light.direction) / np.linalg.norm(light.direction)))
        return si.spawn_ray(dr.zeros(mi.Vector3f, dr.width(si.p)) + d)
    return si.spawn_ray_to(mi.Point3f(*map(float, light.position)))


def visibility(scene, si, light):
    """(V* as Bool, distance to the first occluder as Float, +inf where unoccluded)."""
    ray = shadow_rays(si, light)
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    hit = pi.is_valid()
    return ~hit, dr.select(hit, pi.t, dr.inf)
