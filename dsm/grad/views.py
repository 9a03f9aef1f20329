"""The light's view with its frame in Dr.Jit, so a light's parameters stay in the AD graph.

The kit's views (:mod:`dsm.maps.views`) compute their frame in numpy (``light_frame``) and hold it
as opaque constants: fast, and cut from the graph. Here the view is built the kit's way at the
nominal light (its fit: resolution, extent, cone, near and far), then its origin and axes are
replaced by Dr.Jit expressions of the light's attached values; ``project``, ``depth`` and
``ray_at`` (the kit's code) then differentiate through them.

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

from ..maps.views import OrthographicView, PerspectiveView

MARGIN = 1.15              # the map's square over the image window's (filter taps at the border read real texels)


def light_frame_dr(direction):
    """Right-handed orthonormal (ex, ey, ez) with ez along ``direction`` (mi.Vector3f), in Dr.Jit: the
    construction of :func:`dsm.maps.views.light_frame`, differentiable in the direction."""
    ez = dr.normalize(direction)
    near_z = dr.abs(ez.z) > 0.9
    zero, one = dr.zeros(mi.Float, dr.width(ez)), dr.ones(mi.Float, dr.width(ez))
    helper = mi.Vector3f(dr.select(near_z, one, zero), zero, dr.select(near_z, zero, one))
    ey = dr.normalize(dr.cross(ez, helper))
    ex = dr.cross(ey, ez)
    return ex, ey, ez


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
    view = PerspectiveView((0.0, 0.0, H), (0.0, 0.0, -1.0), cutoff, scene_box(spec), spec.map_resolution)
    # a square frustum: its half side at unit depth is the window's half side over the light's height
    view.tan_half = spec.window * MARGIN / H
    view.T = dr.opaque(mi.Float, view.tan_half)
    view.o = light.position
    view.ex, view.ey, view.ez = light_frame_dr(mi.Vector3f(0.0, 0.0, -1.0))
    view.light_size = spec.light_size
    view.nearest_scene_depth = max(H - scene_box(spec)[1][2], 0.0)
    return _opaque_frame(view)


def directional_view(spec, light, nominal_direction):
    """The orthographic view of a directional light (``light.direction`` attached), fitted to the
    window at ``nominal_direction`` and turned with the attached direction about the point where its
    central ray meets the ground."""
    corners = _window_corners(spec)
    view = OrthographicView(nominal_direction, corners, (corners.min(axis=0), corners.max(axis=0)),
                            spec.map_resolution)
    half = 0.5 * view.extent
    ex0, ey0, ez0 = view.axes_np
    centre = view.origin_np + (ex0 + ey0) * half
    # the map turns about the point where its central ray meets the ground (z = 0): the receivers keep
    # their map positions to first order and the map's texel grid does not sweep over the ground with
    # the lever arm of the map plane's height (which would move every shadow with the grid)
    reach = -centre[2] / ez0[2]
    pivot = mi.Point3f(*(float(c) for c in centre + ez0 * reach))
    ex, ey, ez = light_frame_dr(light.direction)
    view.ex, view.ey, view.ez = ex, ey, ez
    view.o = pivot - ez * reach - (ex + ey) * half
    view.light_size = spec.light_size
    return _opaque_frame(view)


def _opaque_frame(view):
    """The view with its origin and axes evaluated into memory (attached where they were). A component
    that folds to a constant stays a literal otherwise; with the variant set by ``mi.set_variant``
    alone (not dsm.core.env's flags) Dr.Jit 1.5 then updated it in place under the kit's
    ``self.o + ...`` (a directional map's origin took the width of its texels: measured)."""
    dr.make_opaque(view.o, view.ex, view.ey, view.ez)
    return view


def make_view(spec, light, nominal=None):
    """The attached view of ``light`` (a LightState); ``nominal``: the light's parameter values the
    view is fitted at (a directional light's angle), default the spec's."""
    if light.kind in ("point", "area"):          # an area light's map is rendered from its centre
        return point_view(spec, light)
    angle = math.radians(spec.light_angle if nominal is None else nominal)
    return directional_view(spec, light, (math.sin(angle), 0.0, -math.cos(angle)))
