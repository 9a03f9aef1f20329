"""The light's view with its frame in Dr.Jit, so a light's parameters stay in the AD graph.

The kit's views (:mod:`dsm.maps.views`) take their frame at construction, in numpy (opaque
constants: fast, and cut from the graph) or in Dr.Jit. Here a view is fitted the kit's way at the
nominal light (resolution, extent, cone, near and far), and a new view with that fit is built with
the frame as Dr.Jit expressions of the light's attached values (``View.with_frame``;
``light_frame`` of an attached direction); ``project``, ``depth`` and ``ray_at`` (the kit's code)
then differentiate through them.

- Point light: a :class:`~dsm.maps.views.PerspectiveView` from the light's position looking
  down (-z), its square covering the image window with MARGIN to spare; depth along the axis.
- Directional light: an :class:`~dsm.maps.views.OrthographicView` fitted to the window; under a
  new direction the map square turns about its centre (a fixed world point).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..maps.views import OrthographicView, PerspectiveView, light_frame
from .light import MARGIN, positional


def _window_corners(spec) -> np.ndarray:
    w = spec.window * MARGIN
    top = spec.occluder_height + (spec.thickness() if spec.scene == "box" else 0.0)
    return np.array([[x, y, z] for x in (-w, w) for y in (-w, w) for z in (0.0, top)])


def scene_box(spec):
    """(lo, hi) of what the map must hold in depth: the window on the ground up to the occluder's top."""
    c = _window_corners(spec)
    return c.min(axis=0), c.max(axis=0)


def point_view(spec, light):
    """The perspective view of a point light (``light.position`` attached), looking straight down."""
    H = spec.light_height
    reach = spec.window * MARGIN * math.sqrt(2.0) + spec.occluder_size
    cutoff = math.degrees(math.atan(reach / H))
    fitted = PerspectiveView((0.0, 0.0, H), (0.0, 0.0, -1.0), cutoff, scene_box(spec), spec.map_resolution)
    # a square frustum: its half side at unit depth is the window's half side over the light's height
    fitted.tan_half = spec.window * MARGIN / H
    fitted.T = dr.opaque(mi.Float, fitted.tan_half)
    fitted.light_size = spec.light_size
    fitted.nearest_scene_depth = max(H - scene_box(spec)[1][2], 0.0)
    # the fit (depth range) stays the nominal light's, as a central difference's two maps share it: a
    # range refitted at each value would move every normalized depth, which AD (a numpy fit) does not see
    return fitted.with_frame(light.position, *light_frame(mi.Vector3f(0.0, 0.0, -1.0)))


def directional_view(spec, light, nominal_direction):
    """The orthographic view of a directional light (``light.direction`` attached), fitted to the
    window at ``nominal_direction`` and turned with the attached direction about the point where its
    central ray meets the ground (z = 0): the receivers keep their map positions to first order and the
    map's texel grid does not sweep over the ground with the lever arm of the map plane's height (which
    would move every shadow with the grid)."""
    corners = _window_corners(spec)
    fitted = OrthographicView(nominal_direction, corners, (corners.min(axis=0), corners.max(axis=0)),
                              spec.map_resolution)
    centre = fitted.origin_np + (fitted.axes_np[0] + fitted.axes_np[1]) * (0.5 * fitted.extent)
    fitted.light_size = spec.light_size
    return fitted.turned(light.direction, -centre[2] / fitted.axes_np[2][2])


def make_view(spec, light, nominal=None):
    """The attached view of ``light`` (the kit's LightSpec, attached: dsm.grad.light.at); ``nominal``: the
    light's parameter values the view is fitted at (a directional light's angle), default the spec's."""
    if positional(light):          # a spot's perspective map; an area light's is rendered from its centre
        return point_view(spec, light)
    angle = math.radians(spec.light_angle if nominal is None else nominal)
    return directional_view(spec, light, (math.sin(angle), 0.0, -math.cos(angle)))
