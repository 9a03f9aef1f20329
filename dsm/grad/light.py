"""dsm grad's light: a value of the kit's light registry whose position or direction follows the
parameters, and its map's view (the kit's, its frame attached).

The nominal light is read by the registry's own parser (:func:`dsm.lights.get`'s ``parse``) from
the ``[[light]]`` table that ``gradient.light`` stands for, so it is the kit's :class:`LightSpec`
with the kit's checks; :func:`at` returns the same value with its position (a positional light)
or its travel direction (a directional light) replaced by Dr.Jit expressions of the parameters,
attached where a parameter has gradients enabled. Everything that depends on the light's type
asks the registry (``POSITIONAL``, ``SOFT``), never compares names.

The view (:func:`map_view`) is the kit's :class:`~dsm.maps.views.PerspectiveView` (a point or area
light, looking down) or :class:`~dsm.maps.views.OrthographicView` (directional), fitted at the
nominal light and built with its frame as Dr.Jit expressions of the attached light: a perspective
view through ``View.with_frame``, an orthographic one ``turned`` to the attached direction. Its fit
(square, depth range) stays the nominal light's, as a central difference's two maps share it: a range
refitted at each value would move every normalized depth, which AD (a numpy fit) does not see.

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
import numpy as np

from .. import lights
from ..maps.views import OrthographicView, PerspectiveView, light_frame
from . import support

# the map's square over the image window's (filter taps at the border read real texels)
MARGIN = 1.15


def kit_type(grad_light: str) -> str:
    """The kit's light type (dsm.lights.TYPES) that ``gradient.light`` stands for."""
    return {g: kit for kit, g in support.LIGHTS.items()}[grad_light]


def cutoff_deg(spec) -> float:
    """The spot's half angle (degrees): its cone reaches the map square's corners and the occluder's side beyond."""
    reach = spec.window * MARGIN * math.sqrt(2.0) + spec.occluder_size
    # the registry's spot takes at most 85 degrees; the map's square is the view's own (map_view)
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


def map_view(spec, light, top: float):
    """The kit's view of ``light`` (attached: :func:`at`), its square over the image window with MARGIN to
    spare, its depth range the ground (z = 0) up to ``top`` (the occluder's highest point, world)."""
    w = spec.window * MARGIN
    bounds = (np.array([-w, -w, 0.0]), np.array([w, w, top]))
    if positional(light):          # a spot's perspective map; an area light's is rendered from its centre
        H = spec.light_height
        # a square frustum: its half side at unit depth is the window's half side over the light's height
        fitted = PerspectiveView((0.0, 0.0, H), (0.0, 0.0, -1.0), math.degrees(math.atan(w / H)), bounds,
                                 spec.map_resolution, light_size=spec.light_size)
        return fitted.with_frame(light.position, *light_frame(mi.Vector3f(0.0, 0.0, -1.0)))
    a = math.radians(spec.light_angle)
    corners = np.array([[x, y, z] for x in (-w, w) for y in (-w, w) for z in (0.0, top)])
    fitted = OrthographicView((math.sin(a), 0.0, -math.cos(a)), corners, bounds, spec.map_resolution,
                              light_size=spec.light_size)
    # turned about the point where its central ray meets the ground (z = 0): the receivers keep their map
    # positions to first order and the texel grid does not sweep over the ground with the lever arm of the
    # map plane's height (which would move every shadow with the grid)
    centre = fitted.origin_np + (fitted.axes_np[0] + fitted.axes_np[1]) * (0.5 * fitted.extent)
    return fitted.turned(light.direction, -centre[2] / fitted.axes_np[2][2])
