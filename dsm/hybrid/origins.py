"""Where a hybrid's ray starts: four origin rules for a shadow ray leaving a receiver.

- ``spawn``: the kit's rule (:mod:`dsm.scenes.spawn`): along the geometric normal by a bound on the
  hit point's float32 error, ``32 u (max|p| + the triangle's extent)``; the reference's own rays.
- ``mitsuba``: Mitsuba 3.9's ``spawn_ray`` / ``spawn_ray_to``: ``(1 + max|p|) * 8.94e-5`` along the
  normal (a unit term that dwarfs a millimetre scene).
- ``wachter_binder``: Wächter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection",
  Ray Tracing Gems (2019), chapter 6, re-derived from the paper: each coordinate moved by
  ``256 n_i`` units in the last place (its float's bits as an integer), a fixed
  ``n_i / 65536`` where ``|p_i| < 1/32`` (near 0 an ulp is too small to escape the error of the
  hit's computation).
- ``epsilon``: an absolute offset, ``EPSILON`` world units along the normal (the common engine
  constant; right at one scene size only).

Each moves the origin along the geometric normal to the side the ray leaves by. Toward a point
light every rule's ray stops short of the light as the kit's does (:func:`dsm.scenes.spawn.ray_to`).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import lights
from ..core.types import HYBRID_ORIGINS
from ..scenes import spawn
from ..truth import reference
from ..core.suggest import unknown

EPSILON = 1e-4          # world units: the absolute rule's offset (a unit-scale scene's usual choice)
WB_ORIGIN = 1.0 / 32.0            # Wächter & Binder: below this |p_i| the offset is a float, not ulps
WB_FLOAT_SCALE = 1.0 / 65536.0    # the float offset per unit of normal there
WB_INT_SCALE = 256.0              # ulps per unit of normal elsewhere

ORIGINS = HYBRID_ORIGINS


def wachter_binder(p, n):
    """``p`` moved off its surface along ``n`` (Ray Tracing Gems, chapter 6): per coordinate
    ``256 n_i`` ulps away from zero's side of ``p_i``, or ``n_i / 65536`` near zero."""
    out = []
    for pc, nc in zip(p, n):
        step = mi.Int32(WB_INT_SCALE * nc)             # truncated toward zero, as the paper's int cast
        bits = dr.reinterpret_array(mi.Int32, pc)
        moved = dr.reinterpret_array(mi.Float, bits + dr.select(pc < 0, -step, step))
        out.append(dr.select(dr.abs(pc) < WB_ORIGIN, dr.fma(nc, WB_FLOAT_SCALE, pc), moved))
    return mi.Point3f(*out)


def _direction(si, light):
    """(direction toward the light, target point or None for a directional light)."""
    if not lights.get(light.type).POSITIONAL:
        n = dr.width(si.p)
        return dr.zeros(mi.Vector3f, n) - mi.Vector3f(*map(float, np.asarray(light.direction) /
                                                          np.linalg.norm(light.direction))), None
    target = mi.Point3f(*map(float, light.position))
    return target - si.p, target


def _ray_from(o, d, target) -> mi.Ray3f:
    """A ray from origin ``o``: along ``d`` (unbounded), or to ``target`` stopping short as the kit's."""
    if target is None:
        return mi.Ray3f(o, d)
    to = target - o
    dist = dr.norm(to)
    return mi.Ray3f(o, to / dist, dr.maximum(dist - spawn.bound(target), 0.0), 0.0, mi.Color0f())


def rays(si, light, magnitude: float, origin: str) -> mi.Ray3f:
    """Shadow rays from the receivers ``si`` toward ``light`` leaving by origin rule ``origin``."""
    if origin == "spawn":
        return reference.shadow_rays(si, light, magnitude)
    if origin == "mitsuba":
        return reference.shadow_rays(si, light, magnitude, mitsuba_spawn=True)
    d, target = _direction(si, light)
    n_out = dr.select(dr.dot(si.n, d) >= 0, si.n, -si.n)
    if origin == "wachter_binder":
        return _ray_from(wachter_binder(si.p, n_out), d, target)
    if origin == "epsilon":
        return _ray_from(si.p + n_out * EPSILON, d, target)
    raise ValueError(unknown("origin rule", origin, ORIGINS))


def shortened(ray: mi.Ray3f, t_min, t_max) -> mi.Ray3f:
    """``ray`` kept to ``[t_min, t_max]`` from its origin (an empty span: a ray that meets nothing)."""
    o = dr.fma(ray.d, t_min, ray.o)
    maxt = dr.maximum(dr.minimum(ray.maxt, t_max) - t_min, 0.0)
    return mi.Ray3f(o, ray.d, maxt, 0.0, mi.Color0f())
