"""``type = "scene"``: the scene's own lights (a built-in's default light, an XML file's emitters,
a mesh file's default sun), each then of its own type."""
from __future__ import annotations

from ..core.types import LightSpec, check_keys

TYPE = "scene"
POSITIONAL = False
SOFT = False
MOTION = ()
PUNCTUAL_VIEWS = ()


def parse(t: dict, source: str, where: str) -> LightSpec:
    """No keys but the type."""
    check_keys(t, ("type",), source, where)
    return LightSpec(TYPE, label=TYPE)


def views(point_views: tuple, shape: str) -> tuple:
    """None of its own: each light it stands for has its type's views."""
    return ()


def make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale):
    """Never called: the scene's lights stand in for this entry before any view is made."""
    raise ValueError("a 'scene' light stands for the scene's own lights and has no view of its own")


def emitter(light, strength: float):
    """Never called: the scene's lights are its own emitters already."""
    raise ValueError("a 'scene' light stands for the scene's own emitters and has no emitter of its own")
