"""Light types: one module each, listed explicitly, each meeting :class:`base.LightType`.

Everything that depends on a light's type (its [[light]] keys, the views the plan gives it, its
view, whether it sits at a point, the motion paths it follows, whether its reference is soft)
is asked of its module here, so a new light type is a module and a line in REGISTRY.
"""
from __future__ import annotations

from . import area, directional, point, scene, spot
from .base import LightType, unit_direction
from ..core.suggest import unknown

REGISTRY = {m.TYPE: m for m in (scene, directional, spot, point, area)}
TYPES = tuple(REGISTRY)

_broken = [name for name, m in REGISTRY.items() if not isinstance(m, LightType)]
if _broken:
    raise ImportError(f"light types not meeting base.LightType: {_broken}")


def get(light_type: str):
    """The module of ``light_type`` (a ValueError naming the valid types)."""
    try:
        return REGISTRY[light_type]
    except KeyError:
        raise ValueError(unknown("light type", light_type, TYPES)) from None


def emitter(light, strength: float = 1.0) -> dict:
    """``light`` (a LightSpec) as a Mitsuba emitter dict of ``strength``, from its type's module."""
    return get(light.type).emitter(light, strength)


def is_soft(light) -> bool:
    """Whether the light's exact visibility is a visible fraction (an area light), not one ray."""
    return get(light.type).SOFT
