"""The contract every light type meets (:class:`LightType`), and the parsing its types share.

A light type is a module: ``TYPE`` (its ``[[light]] type``), ``POSITIONAL`` (whether it sits at a
point: its shadow rays end there and a receiver may lie outside its domain; a directional light
reaches everywhere), ``MOTION`` (the ``[[motion]]`` light paths it follows), ``parse(table,
source, where) -> LightSpec`` (its ``[[light]]`` table, keys checked), ``views(point_views,
shape) -> tuple`` (the view kinds the plan gives it) and ``make_view(light, R, receivers_world,
bbox, kind, cascade, sensor, scale)``, ``emitter(light, strength)`` (the light as a Mitsuba emitter
dict, for a renderer's image of the same scene: dsm grad --compare); ``SOFT``: whether its exact visibility is a visible fraction
(dsm.truth.area's Monte Carlo reference) rather than one shadow ray; ``PUNCTUAL_VIEWS`` the view
kinds a ``[map.virtual]`` of rule punctual replaces (dsm.maps.virtual_punctual). A new light type is a module here and a line in
``lights/__init__.py``'s registry.
"""
from __future__ import annotations

import math
from typing import Any, Protocol, runtime_checkable

from ..core.types import ConfigError, vec3


@runtime_checkable
class LightType(Protocol):
    """The contract of a light type module: its constants and its ``parse``, ``views`` and ``make_view``."""
    TYPE: str
    POSITIONAL: bool
    SOFT: bool
    MOTION: tuple
    PUNCTUAL_VIEWS: tuple       # the view kinds a punctual virtual map replaces (spot: perspective, point: cube)

    def parse(self, t: dict, source: str, where: str) -> Any:
        """The light's LightSpec from its [[light]] table (ConfigError naming the key)."""

    def views(self, point_views: tuple, shape: str) -> tuple:
        """The view kinds the plan gives this light."""

    def make_view(self, light, R, receivers_world, bbox, kind, cascade, sensor, scale) -> Any:
        """The light's view of kind ``kind`` at resolution R."""

    def emitter(self, light, strength: float) -> dict:
        """The light as a Mitsuba emitter dict of ``strength`` (an area light's: a shape carrying one)."""


def rgb(strength: float) -> dict:
    """A Mitsuba RGB value of ``strength`` in every channel (an emitter's intensity, irradiance or radiance)."""
    return {"type": "rgb", "value": float(strength)}


def unit_direction(raw, source: str, key: str) -> tuple:
    """A light's direction as a unit vector normalized in float64 (any finite, nonzero input)."""
    # [1e308, 1e308, -1e308] or [1e-300, 0, -1e-300] over- or underflow when squared (float32
    # already beyond about 1e19 or below 1e-19): every pixel read as backfacing, the case empty.
    # Dividing by the largest component first keeps every step in range
    v = vec3(raw, source, key, nonzero=True)
    big = max(abs(c) for c in v)
    u = [c / big for c in v]
    n = math.sqrt(sum(c * c for c in u))
    return tuple(c / n for c in u)


def required(t: dict, key: str, source: str, where: str, what: str):
    """``t[key]``, or a ConfigError saying the light ``what`` needs it."""
    if key not in t:
        raise ConfigError(source, f"{where}.{key}", f"a {what} light needs a {key}")
    return t[key]
