"""A point light: paraboloid, dual paraboloid or cube maps around its position, or a voxelized shadow volume."""
from __future__ import annotations

from ..core.types import LightSpec, check_keys, vec3
from ..maps import virtual_punctual
from ..maps.vsv import EpipolarView, camera_pose
from ..maps.views import CubeView, ParaboloidView
from .base import required, rgb, unit_direction
from ..core.suggest import unknown

TYPE = "point"
POSITIONAL = True
SOFT = False
MOTION = ("move", "keyframes")
PUNCTUAL_VIEWS = ("cube",)          # the view a punctual virtual map ([map.virtual] rule punctual) replaces


def parse(t: dict, source: str, where: str) -> LightSpec:
    """``position``; ``direction``: the paraboloid's axis (its hemisphere), the dual paraboloid's front map."""
    check_keys(t, ("type", "position", "direction"), source, where)
    pos = vec3(required(t, "position", source, where, TYPE), source, f"{where}.position")
    d = unit_direction(t.get("direction", [0.0, 0.0, -1.0]), source, f"{where}.direction")
    return LightSpec(TYPE, position=pos, direction=d, label=TYPE)


def views(point_views: tuple, shape: str) -> tuple:
    """The config's point-light views (``[map] point_views``)."""
    return tuple(point_views)


def make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale):
    """A paraboloid, dual-paraboloid or cube view at the light's position, or the VSV grid of the
    light and the camera ``sensor`` fitted to the receivers (dsm.maps.vsv)."""
    axis = light.direction if light.direction is not None else (0.0, 0.0, -1.0)
    if kind in ("paraboloid", "dual_paraboloid"):
        return ParaboloidView(light.position, axis, bbox, R, dual=kind == "dual_paraboloid")
    if kind == "cube" and getattr(cascade, "virtual", False):      # [map.virtual] rule punctual
        return virtual_punctual.cube_view(light, cascade, receivers_world, bbox, sensor, scale)
    if kind == "cube":
        return CubeView(light.position, bbox, R)
    if kind == "vsv":
        eye, up = camera_pose(sensor)
        return EpipolarView(light.position, eye, up, receivers_world, bbox, R)
    raise ValueError(unknown("point-light view", kind, ("paraboloid", "dual_paraboloid", "cube", "vsv")))


def emitter(light, strength: float) -> dict:
    """Mitsuba's point emitter at the light's position, intensity ``strength``."""
    return {"type": "point", "position": [float(c) for c in light.position], "intensity": rgb(strength)}
