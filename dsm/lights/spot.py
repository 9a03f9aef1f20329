"""A spot light: a perspective map along its axis, within its cutoff; a voxelized shadow volume on request."""
from __future__ import annotations

import numpy as np

from ..core.types import ConfigError, LightSpec, check_keys, number, vec3
from ..maps import virtual_punctual
from ..maps.vsv import EpipolarView, camera_pose
from ..maps.views import PerspectiveView
from .base import required, rgb, unit_direction

TYPE = "spot"
POSITIONAL = True
SOFT = False
MOTION = ("move", "keyframes")
PUNCTUAL_VIEWS = ("perspective",)   # the view a punctual virtual map ([map.virtual] rule punctual) replaces  # translated, or along keyframes (aimed at their targets)


def parse(t: dict, source: str, where: str) -> LightSpec:
    """``position``, exactly one of ``target`` or ``direction``, ``cutoff`` (half angle, degrees)."""
    check_keys(t, ("type", "position", "target", "direction", "cutoff"), source, where)
    pos = vec3(required(t, "position", source, where, TYPE), source, f"{where}.position")
    if ("target" in t) == ("direction" in t):
        raise ConfigError(source, where, "a spot light needs exactly one of target or direction",
                          ("target", "direction"))
    target = vec3(t["target"], source, f"{where}.target") if "target" in t else None
    direction = unit_direction(t["direction"], source, f"{where}.direction") if "direction" in t else None
    if target is not None and target == pos:
        raise ConfigError(source, f"{where}.target", "the target equals the position")
    cutoff = number(t.get("cutoff", 30.0), source, f"{where}.cutoff", positive=True, maximum=85.0)
    return LightSpec(TYPE, position=pos, target=target, direction=direction, cutoff=cutoff, label=TYPE)


def views(point_views: tuple, shape: str) -> tuple:
    """One perspective view, and a VSV grid when the config's ``[map] view`` names ``vsv``."""
    return ("perspective",) + (("vsv",) if "vsv" in point_views else ())


def make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale):
    """The perspective map along the spot's axis (its direction, or toward its target); ``kind``
    "vsv": the VSV grid of the light and the camera ``sensor`` over the same cone (dsm.maps.vsv);
    ``cascade`` a VirtualSpec: its virtual shadow map for ``sensor`` (dsm.maps.virtual_punctual)."""
    if getattr(cascade, "virtual", False):
        return virtual_punctual.spot_view(light, cascade, receivers_world, bbox, sensor, scale)
    axis = light.direction if light.direction is not None else np.subtract(light.target, light.position)
    view = PerspectiveView(light.position, axis, light.cutoff, bbox, R)
    if kind != "vsv":
        return view
    eye, up = camera_pose(sensor)
    return EpipolarView(light.position, eye, up, receivers_world, bbox, R, domain=view.inside)


def emitter(light, strength: float) -> dict:
    """Mitsuba's spot emitter along the light's axis, intensity ``strength``, with no falloff inside its
    cutoff (``beam_width`` = ``cutoff_angle``): a point light within its cone, as the map reads it."""
    import mitsuba as mi
    pos = np.asarray(light.position, float)
    axis = np.asarray(light.direction if light.direction is not None else np.subtract(light.target, pos), float)
    up = [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 * np.linalg.norm(axis) else [1.0, 0.0, 0.0]
    to_world = mi.ScalarTransform4f().look_at(origin=list(pos), target=list(pos + axis), up=up)
    return {"type": "spot", "to_world": to_world, "cutoff_angle": float(light.cutoff),
            "beam_width": float(light.cutoff), "intensity": rgb(strength)}
