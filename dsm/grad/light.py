"""dsm grad's light: a value of the kit's light registry whose position or direction follows the parameters.

The nominal light is read by the registry's own parser (:func:`dsm.lights.get`'s ``parse``) from
the ``[[light]]`` table that ``gradient.light`` stands for, so it is the kit's :class:`LightSpec`
with the kit's checks; :func:`at` returns the same value with its position (a positional light)
or its travel direction (a directional light) replaced by Dr.Jit expressions of the parameters,
attached where a parameter has gradients enabled. Everything that depends on the light's type
asks the registry (``POSITIONAL``, ``SOFT``), never compares names.

``gradient.light`` -> kit type: ``point`` is a spot straight down (one perspective map looking
down, the kit's spot view; the kit's point light has cube and paraboloid views, which dsm grad does
not differentiate: :mod:`.support`), ``directional`` and ``area`` (a square of side ``light_size``
facing down) are themselves.
"""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi

from .. import lights
from . import support

# the map's square over the image window's (filter taps at the border read real texels)
MARGIN = 1.15


def kit_type(grad_light: str) -> str:
    """The kit's light type (dsm.lights.TYPES) that ``gradient.light`` stands for."""
    return {g: kit for kit, g in support.LIGHTS.items()}[grad_light]


def cutoff_deg(spec) -> float:
    """The spot's half angle (degrees): its cone reaches the map square's corners and the occluder's side beyond."""
    reach = spec.window * MARGIN * math.sqrt(2.0) + spec.occluder_size
    # the registry's spot takes at most 85 degrees; the map's square is the view's own (grad.views)
    return min(math.degrees(math.atan(reach / spec.light_height)), 85.0)


def table(spec) -> dict:
    """The ``[[light]]`` table (world units) of the spec's light at its nominal values."""
    kind = kit_type(spec.light)
    down = [0.0, 0.0, -1.0]
    above = [0.0, 0.0, spec.light_height]
    if kind == "spot":
        return {"type": kind, "position": above, "direction": down, "cutoff": cutoff_deg(spec)}
    if kind == "area":
        return {"type": kind, "shape": "rectangle", "position": above, "direction": down, "size": spec.light_size}
    a = math.radians(spec.light_angle)
    return {"type": kind, "direction": [math.sin(a), 0.0, -math.cos(a)]}


def nominal(spec):
    """The spec's light as the kit's LightSpec, read by the light registry's parser."""
    t = table(spec)
    return lights.get(t["type"]).parse(t, spec.source, "gradient.light")


def positional(light) -> bool:
    """Whether ``light`` sits at a point (its shadow rays end there), from the light registry."""
    return lights.get(light.type).POSITIONAL


def at(light, values: dict):
    """``light`` (a LightSpec) at parameter ``values`` (Dr.Jit scalars): a positional light's position
    (x, 0, height) or a directional light's travel direction tilted toward +x, as Dr.Jit expressions."""
    zero = dr.zeros(mi.Float, 1)
    if positional(light):
        return dataclasses.replace(light, position=mi.Point3f(values["light_x"], zero, values["light_height"]))
    a = values["light_angle"] * (math.pi / 180.0)
    return dataclasses.replace(light, direction=mi.Vector3f(dr.sin(a), zero, -dr.cos(a)))


def floats(light, values: dict):
    """``light`` at parameter ``values`` (floats) with plain float position and direction (the exact side's)."""
    if positional(light):
        return dataclasses.replace(light, position=(float(values["light_x"]), 0.0, float(values["light_height"])))
    a = math.radians(float(values["light_angle"]))
    return dataclasses.replace(light, direction=(math.sin(a), 0.0, -math.cos(a)))
