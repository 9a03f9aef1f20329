"""A directional light (the sun): an orthographic map fitted to the receivers, or cascades."""
from __future__ import annotations

from ..maps import cascades, virtual
from ..core.types import LightSpec, check_keys
from ..maps.views import OrthographicView
from .base import required, rgb, unit_direction

TYPE = "directional"
POSITIONAL = False              # every receiver is in its domain; shadow rays go along -direction
SOFT = False
MOTION = ("turn",)              # [[motion]] light = "turn": its direction turned about an axis
PUNCTUAL_VIEWS = ()             # its virtual maps are clipmaps (dsm.maps.virtual), never punctual


def parse(t: dict, source: str, where: str) -> LightSpec:
    """``direction`` (the way the light travels)."""
    check_keys(t, ("type", "direction"), source, where)
    d = unit_direction(required(t, "direction", source, where, TYPE), source, f"{where}.direction")
    return LightSpec(TYPE, direction=d, label=TYPE)


def views(point_views: tuple, shape: str) -> tuple:
    """One orthographic view (a cascade layout makes it cascaded)."""
    return ("orthographic",)


def make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale):
    """The orthographic map fitted to the receivers, or the cascades of ``cascade`` (a CascadeSpec), or
    the virtual shadow map of ``cascade`` (a VirtualSpec), for ``sensor``."""
    if getattr(cascade, "virtual", False):
        return virtual.make_view(light, cascade, receivers_world, bbox, sensor, scale)
    if cascade is not None:
        return cascades.make_view(light, cascade, R, receivers_world, bbox, sensor, scale)
    return OrthographicView(light.direction, receivers_world, bbox, R)


def emitter(light, strength: float) -> dict:
    """Mitsuba's directional emitter along the light's direction, irradiance ``strength``."""
    return {"type": "directional", "direction": [float(c) for c in light.direction], "irradiance": rgb(strength)}
