"""An area light (dsm.truth.area): a sphere, disk, rectangle or the scene's own area emitters, its map
cast from its centre and its exact visibility a Monte Carlo estimate."""
from __future__ import annotations

import math

import numpy as np

from . import area_surface
from ..core.types import AREA_SHAPES, ConfigError, LightSpec, as_list, check_keys, choice, number, vec3
from .base import rgb, unit_direction

TYPE = "area"
POSITIONAL = True
SOFT = True                     # its reference is the visible fraction V* (dsm.truth.area), not one ray
MOTION = ()
PUNCTUAL_VIEWS = ()             # no punctual virtual map (dsm.maps.virtual_punctual)
SAMPLING = ("min_samples", "max_samples", "tolerance", "confidence", "replicates")
SHAPE_KEYS = {"emitter": (), "sphere": ("position", "size"), "disk": ("position", "direction", "size"),
              "rectangle": ("position", "direction", "size")}


def _sampling(t: dict, source: str, where: str) -> dict:
    """The reference's sampling: min_samples, max_samples (whole replicates each), tolerance,
    confidence and replicates."""
    reps = number(t.get("replicates", 16), source, f"{where}.replicates", integer=True, minimum=2, maximum=64)
    lo = number(t.get("min_samples", 16), source, f"{where}.min_samples", integer=True, minimum=reps,
                maximum=1 << 20)
    hi = number(t.get("max_samples", 4096), source, f"{where}.max_samples", integer=True, minimum=lo,
                maximum=1 << 20)
    for key, value in (("min_samples", lo), ("max_samples", hi)):
        if value % reps:
            raise ConfigError(source, f"{where}.{key}", f"{value} is not a multiple of replicates = {reps} "
                              f"(each replicate takes the same number of samples); try {value - value % reps or reps}")
    tol = number(t.get("tolerance", 0.01), source, f"{where}.tolerance", minimum=0.0, maximum=1.0)
    conf = number(t.get("confidence", 0.99), source, f"{where}.confidence", minimum=0.5, maximum=0.999999)
    return {"min_samples": lo, "max_samples": hi, "tolerance": tol, "confidence": conf, "replicates": reps}


def _size(t: dict, shape: str, source: str, where: str) -> tuple:
    """A side or diameter, or a rectangle's [width, height]."""
    raw = t["size"]
    if shape == "rectangle" and isinstance(raw, list):
        if len(raw) != 2:
            raise ConfigError(source, f"{where}.size", f"expected a side or [width, height], got {raw!r}")
        return tuple(number(x, source, f"{where}.size", positive=True) for x in raw)
    return (number(raw, source, f"{where}.size", positive=True),)


def parse(t: dict, source: str, where: str) -> LightSpec:
    """``shape``, ``position``, ``direction`` (the normal), ``size``, ``scenes`` and the reference's sampling."""
    shape = choice(t.get("shape"), source, f"{where}.shape", AREA_SHAPES)
    check_keys(t, ("type", "shape", "scenes") + SHAPE_KEYS[shape] + SAMPLING, source, where)
    only = as_list(t.get("scenes", []))
    if not all(isinstance(x, str) and x for x in only):
        raise ConfigError(source, f"{where}.scenes", f"expected a list of scene labels, got {t['scenes']!r}")
    sampling = _sampling(t, source, where)
    pos = direction = None
    size = ()
    if shape != "emitter":
        for key in ("position", "size"):
            if key not in t:
                raise ConfigError(source, f"{where}.{key}", f"a {shape} light needs a {key}")
        pos = vec3(t["position"], source, f"{where}.position")
        size = _size(t, shape, source, where)
        if shape != "sphere":
            direction = unit_direction(t.get("direction", [0.0, 0.0, -1.0]), source, f"{where}.direction")
    return LightSpec(TYPE, position=pos, direction=direction, label=TYPE, shape=shape, size=size,
                     scenes=tuple(only), **sampling)


def views(point_views: tuple, shape: str) -> tuple:
    """A sphere's: the point-light views but a VSV grid (a hard light's); a one-sided light's: one view fitted to it."""
    return tuple(v for v in point_views if v != "vsv") if shape == "sphere" else ("fitted",)


def make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale):
    """The view from the luminaire's centre (:func:`dsm.lights.area_surface.make_view`)."""
    return area_surface.make_view(light, R, receivers_world, bbox, kind)


def emitter(light, strength: float) -> dict:
    """The luminaire as a Mitsuba shape carrying an area emitter of radiance ``strength``: a rectangle or
    a disk (Mitsuba's face +z, turned to the light's normal; one-sided, as the reference samples it) or
    a sphere; an emitter light is the scene's own already."""
    import mitsuba as mi
    if light.shape == "emitter":
        raise ValueError("an area light of shape 'emitter' is the scene's own emitters and has no emitter of its own")
    pos = [float(c) for c in light.position]
    out = {"emitter": {"type": "area", "radiance": rgb(strength)}}
    if light.shape == "sphere":
        return {"type": "sphere", "center": pos, "radius": 0.5 * float(light.size[0]), **out}
    # a side or [width, height]; a disk's diameter (Mitsuba's disk has radius 1, its rectangle half side 1)
    w, h = (light.size * 2)[:2] if len(light.size) == 1 else light.size[:2]
    turn = _turn_from_z(light.direction)
    to_world = mi.ScalarTransform4f().translate(pos).rotate(*turn).scale([w / 2.0, h / 2.0, 1.0])
    return {"type": light.shape, "to_world": to_world, **out}


def _turn_from_z(direction) -> tuple:
    """(axis, degrees) of the rotation taking +z to ``direction`` (a half turn about x for -z)."""
    z, d = np.array([0.0, 0.0, 1.0]), np.asarray(direction, float) / np.linalg.norm(direction)
    axis = np.cross(z, d)
    degrees = math.degrees(math.atan2(float(np.linalg.norm(axis)), float(z @ d)))
    return (list(axis / np.linalg.norm(axis)) if np.linalg.norm(axis) > 1e-12 else [1.0, 0.0, 0.0]), degrees
