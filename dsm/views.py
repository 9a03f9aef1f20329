"""Light views: how a light's shadow map is parameterized.

A view maps world points to continuous map coordinates ``(u, v)`` in texel units (texel
``(i, j)`` covers ``[i, i+1) x [j, j+1)``), gives each point its depth in the view's metric
(world units) and the ray through any map position. Scalars a sweep may change (frame,
extent, resolution) are opaque Dr.Jit values, so one kernel serves every map of a kind.

- ``OrthographicView`` (directional light): depth is the distance along the light
  direction; the map is a square fitted tightly around the receivers in light space, its
  depth range to the whole scene's bounds (every possible caster), as seed 002 recommends.
- ``PerspectiveView`` (spot light): rays from the light position, depth is the distance
  along the light's axis; the square map covers the cone.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np


def light_frame(direction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed orthonormal (ex, ey, ez) with ez along ``direction``, stable for any axis."""
    ez = np.asarray(direction, dtype=np.float64)
    ez = ez / np.linalg.norm(ez)
    helper = np.array([1.0, 0.0, 0.0]) if abs(ez[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    ey = np.cross(ez, helper)
    ey /= np.linalg.norm(ey)
    ex = np.cross(ey, ez)
    return ex, ey, ez


def _opaque_vec(v):
    return mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in v))


def _bbox_corners(bbox_min, bbox_max) -> np.ndarray:
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])


class View:
    """Common part: a frame (origin ``o``, axes ``ex``, ``ey``, ``ez``) and the depth metric."""

    kind = "view"

    def __init__(self, origin, ex, ey, ez, resolution: int, near: float, far: float):
        self.resolution = int(resolution)
        self.origin_np = np.asarray(origin, float)
        self.axes_np = (np.asarray(ex, float), np.asarray(ey, float), np.asarray(ez, float))
        self.near, self.far = float(near), float(far)
        self.o = _opaque_vec(origin)
        self.ex, self.ey, self.ez = (_opaque_vec(a) for a in self.axes_np)
        self.R = dr.opaque(mi.Float, float(resolution))
        self.R_u = dr.opaque(mi.UInt32, int(resolution))

    @property
    def depth_range(self) -> float:
        return self.far - self.near

    def local(self, p):
        q = p - self.o
        return dr.dot(q, self.ex), dr.dot(q, self.ey), dr.dot(q, self.ez)

    def depth(self, p):
        """Depth of world point ``p`` in the view's metric (world units)."""
        return dr.dot(p - self.o, self.ez)

    def depth_on_plane(self, u, v, p0, n):
        """Depth where the ray through map position (u, v) meets the plane (p0, n).

        +inf where the ray is parallel to the plane (no NaN ever leaves here).
        """
        o, d = self.ray_at(u, v)
        den = dr.dot(d, n)
        t = dr.dot(p0 - o, n) / dr.select(den != 0, den, 1.0)
        depth = self.depth(o) + t * dr.dot(d, self.ez)
        return dr.select((den != 0) & dr.isfinite(depth), depth, dr.inf)

    def texel_rays(self, first: int, count: int) -> mi.Ray3f:
        """Rays through the centres of texels ``first .. first + count - 1`` (row-major)."""
        idx = dr.arange(mi.UInt32, first, first + count)
        i, j = idx % self.R_u, idx // self.R_u
        o, d = self.ray_at(mi.Float(i) + 0.5, mi.Float(j) + 0.5)
        return mi.Ray3f(o, d)


class OrthographicView(View):
    kind = "orthographic"

    def __init__(self, direction, receivers_world: np.ndarray, scene_bbox, resolution: int):
        ex, ey, ez = light_frame(direction)
        pts = np.asarray(receivers_world, float).reshape(-1, 3)
        if len(pts) == 0:
            pts = _bbox_corners(*scene_bbox)
        xs, ys = pts @ ex, pts @ ey
        corners = _bbox_corners(*scene_bbox)
        zs = corners @ ez
        diag = float(np.linalg.norm(np.asarray(scene_bbox[1]) - np.asarray(scene_bbox[0])))
        extent = max(xs.max() - xs.min(), ys.max() - ys.min())
        if not extent > 0:     # a single receiver or a degenerate scene: any positive width works
            extent = max(diag, 1.0) * 1e-3
        margin = 0.01 * max(zs.max() - zs.min(), diag, 1e-30)
        cx, cy = 0.5 * (xs.max() + xs.min()), 0.5 * (ys.max() + ys.min())
        z0 = zs.min() - margin
        origin = ex * (cx - extent / 2) + ey * (cy - extent / 2) + ez * z0
        self.extent = float(extent)
        super().__init__(origin, ex, ey, ez, resolution, near=0.0, far=float(zs.max() - z0 + margin))
        self.L = dr.opaque(mi.Float, self.extent)

    def project(self, p):
        x, y, _ = self.local(p)
        s = self.R / self.L
        return x * s, y * s

    def ray_at(self, u, v):
        s = self.L / self.R
        o = self.o + self.ex * (u * s) + self.ey * (v * s)
        return o, dr.zeros(mi.Vector3f, dr.width(o)) + self.ez

    def texel_world(self, p):
        return dr.zeros(mi.Float, dr.width(p)) + self.L / self.R

    def to_light(self, p):
        return dr.zeros(mi.Vector3f, dr.width(p)) - self.ez

    def inside(self, p):
        u, v = self.project(p)
        return (u >= 0) & (u <= self.R) & (v >= 0) & (v <= self.R)


class PerspectiveView(View):
    kind = "perspective"

    def __init__(self, position, axis, cutoff_deg: float, scene_bbox, resolution: int):
        ex, ey, ez = light_frame(axis)
        corners = _bbox_corners(*scene_bbox)
        zs = (corners - np.asarray(position, float)) @ ez
        self.cutoff = float(cutoff_deg)
        self.tan_half = math.tan(math.radians(self.cutoff))
        far = max(float(zs.max()), 1e-30)
        super().__init__(position, ex, ey, ez, resolution, near=0.0, far=far * 1.01)
        self.T = dr.opaque(mi.Float, self.tan_half)
        self.cos_cut = dr.opaque(mi.Float, math.cos(math.radians(self.cutoff)))

    def project(self, p):
        x, y, z = self.local(p)
        s = self.R * 0.5 / (self.T * z)
        return (x * s + self.R * 0.5), (y * s + self.R * 0.5)

    def ray_at(self, u, v):
        a = (2.0 * u / self.R - 1.0) * self.T
        b = (2.0 * v / self.R - 1.0) * self.T
        d = dr.normalize(self.ex * a + self.ey * b + self.ez)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        return 2.0 * self.T * self.depth(p) / self.R

    def to_light(self, p):
        return dr.normalize(self.o - p)

    def inside(self, p):
        x, y, z = self.local(p)
        in_cone = z >= dr.norm(p - self.o) * self.cos_cut
        return (z > 0) & in_cone & (dr.abs(x) <= self.T * z) & (dr.abs(y) <= self.T * z)
