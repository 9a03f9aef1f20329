"""Voxelized shadow volumes (Wyman, "Voxelized shadow volumes", HPG 2011) as a view of the kit.

A VSV is a binary voxel grid in epipolar space, defined by the eye E and the light L. A world
point P is ``(theta, phi, alpha)``: ``theta`` the epipolar plane (the half-plane bounded by the
line E-L that holds P), measured about that line from the camera's up vector; ``phi`` the light
ray within the plane, the angle at L between L->E and L->P; ``alpha`` the view ray, the angle at
E between E->L and E->P (Dou et al. 2014, section 3.3). Along a light ray ``alpha`` grows
monotonically away from the light (from 0 at L to ``pi - phi`` at infinity), so "past the first
hit" is "larger alpha".

**The grid.** ``theta`` and ``phi`` are split into ``R x R`` cells (the map's resolution), each
over the range the receivers span (``theta`` the shortest arc holding them all), with
MARGIN_CELLS cells to spare on each side; ``alpha`` over the receivers' range with 1 % to spare
on each side, split into ``N`` voxels by the lookup scheme (its ``alpha`` parameter, so one
build serves every alpha resolution). The view's one depth function is the fraction of that
alpha range, ``(alpha - alpha_0) / (alpha_1 - alpha_0)``: ``N`` times it is the alpha voxel
coordinate ``s`` (voxel ``k`` covers ``[k, k + 1)``, its centre at ``k + 1/2``).

**The build: ray casting, not rasterization.** One ray from the light per ``(theta, phi)`` cell,
through the cell's centre (``View.texel_rays`` and :mod:`dsm.maps.shadowmap`, the kit's map build:
``z1`` is the first hit's depth). The voxels of the cell's column past the first hit are
occluded; the hit's own voxel is occluded when its centre lies past the hit (``occupancy =
"centre"``, the default: each voxel takes the shadow state at its centre, as Wyman's resampling
gives and as Dou et al.'s figure 5 needs, where the voxel holding the surface is lit when the
surface lies behind its centre) or always (``occupancy = "hit"``: a voxel holding an occluding
surface is occluded, Dou et al.'s figure 4 caption read literally). A column is a step function
of ``k``, so the binary column is stored exactly as its first occluded voxel
(:func:`first_occluded`); :func:`voxels` expands it.
Wyman builds the grid by rasterization instead: a shadow map is rendered and resampled into
epipolar space, each shadow-map texel marking where its light ray enters shadow, then a prefix
scan along each view ray fills the shadowed voxels. That resampling adds a second discretization
(the shadow map's texels) and its own aliasing; here each column's shadow comes from its own
exact ray, so the only discretization measured is the voxel grid's.

Known limits: the grid is fitted to one camera and one light (a VSV is view-dependent); a
receiver on the eye-light line has no epipolar plane (theta is taken as 0 there); angles are
float32 (``atan2``), so alpha voxels narrower than about 1e-5 radians lose precision.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .views import View, light_frame

MARGIN_CELLS = 2          # theta and phi cells spared on each side of the receivers' range
ALPHA_MARGIN = 0.01       # fraction of the receivers' alpha range spared on each side
OCCUPANCY = ("centre", "hit")
MAX_ALPHA = 1 << 16       # alpha voxels at most: float32 depth (24 bits) keeps s to 1/256 of a voxel
TWO_PI = 2.0 * math.pi


def camera_pose(sensor) -> tuple[np.ndarray, np.ndarray]:
    """(eye position, up vector) of a Mitsuba sensor in world space, float64."""
    m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    return m[:3, 3].copy(), m[:3, 1] / np.linalg.norm(m[:3, 1])


def epipolar_frame(light_world, eye_world, up_world) -> tuple:
    """(ex, ey, ez, D): ez from the light toward the eye, ex the camera's up made perpendicular to
    it (theta = 0), ey = ez x ex; D the eye-light distance. ValueError when the eye is at the light."""
    axis = np.asarray(eye_world, float) - np.asarray(light_world, float)
    dist = float(np.linalg.norm(axis))
    if not dist > 0:
        raise ValueError("voxelized shadow volume: the camera sits at the light (no epipolar planes)")
    ez = axis / dist
    ex = np.asarray(up_world, float) - ez * float(np.dot(up_world, ez))
    if np.linalg.norm(ex) < 1e-9:          # the camera's up along the eye-light line: any perpendicular
        ex = light_frame(ez)[0]
    ex = ex / np.linalg.norm(ex)
    return ex, np.cross(ez, ex), ez, dist


def angles_np(p_world, light_world, frame) -> tuple:
    """(theta in [0, 2 pi), phi, alpha) of world points (n, 3) in float64 (the fit's and the tests')."""
    ex, ey, ez, dist = frame
    q = np.asarray(p_world, float).reshape(-1, 3) - np.asarray(light_world, float)
    x, y, z = q @ ex, q @ ey, q @ ez
    radial = np.hypot(x, y)
    return np.mod(np.arctan2(y, x), TWO_PI), np.arctan2(radial, z), np.arctan2(radial, dist - z)


def shortest_arc(theta) -> tuple[float, float]:
    """(start, length) of the shortest arc of the circle holding every angle of ``theta``."""
    t = np.sort(np.asarray(theta, float))
    if len(t) < 2:
        return (float(t[0]) if len(t) else 0.0), 0.0
    gaps = np.diff(np.concatenate([t, [t[0] + TWO_PI]]))
    k = int(np.argmax(gaps))
    start = t[(k + 1) % len(t)]
    return float(start), float(TWO_PI - gaps[k])


def _padded(lo: float, span: float, cells: float, floor_span: float) -> tuple[float, float]:
    """(start, span) of a range grown so that ``cells`` of its R cells lie on each side of it."""
    span = max(span, floor_span)
    grown = span * (1.0 + 2.0 * cells)
    return lo - (grown - span) / 2.0, grown


def fit_ranges(theta, phi, alpha, R: int) -> tuple:
    """(theta_0, theta span, phi_0, phi span, alpha_0, alpha span) of a grid of R x R cells holding
    the receivers' angles: MARGIN_CELLS cells to spare in theta and phi (at most R / 8), theta the
    shortest arc (the whole circle when it would exceed it), ALPHA_MARGIN of alpha's range."""
    spare = min(MARGIN_CELLS, R // 8)
    cells = spare / max(R - 2 * spare, 1)
    t0, t_span = _padded(*shortest_arc(theta), cells, 1e-6)
    if t_span >= TWO_PI:                   # the receivers surround the eye-light line: the whole circle
        t0, t_span = float(np.min(theta)), TWO_PI
    p0, p_span = _padded(float(np.min(phi)), float(np.ptp(phi)), cells, 1e-6)
    a_span = max(float(np.ptp(alpha)), 1e-6)
    a0 = float(np.min(alpha)) - ALPHA_MARGIN * a_span
    return float(np.mod(t0, TWO_PI)), t_span, p0, p_span, a0, a_span * (1.0 + 2.0 * ALPHA_MARGIN)


class EpipolarView(View):
    """A VSV's grid as a view: (u, v) the theta and phi cells, depth the fraction of the alpha range."""
    kind = "vsv"
    depth_oracles = False     # the oracles are depth biases of a depth map; a binary grid has none

    def __init__(self, light_world, eye_world, up_world, receivers_world, scene_bbox, resolution: int,
                 domain=None):
        self.frame = epipolar_frame(light_world, eye_world, up_world)
        ex, ey, ez, dist = self.frame
        pts = np.asarray(receivers_world, float).reshape(-1, 3)
        if len(pts) == 0:                  # no receivers: the scene's corners give the ranges
            lo, hi = (np.asarray(b, float) for b in scene_bbox)
            pts = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
        R = int(resolution)
        (self.theta0, self.theta_span, self.phi0, self.phi_span, self.alpha0,
         self.alpha_span) = fit_ranges(*angles_np(pts, light_world, self.frame), R)
        self.domain = domain               # a spot's cone (its perspective view's inside), else None
        # what the columns depend on beside the frame (a moving camera's frames rebuild when it changes)
        self.extents = np.array([self.theta0, self.theta_span, self.phi0, self.phi_span, self.alpha0,
                                 self.alpha_span, dist])
        super().__init__(light_world, ex, ey, ez, R, near=0.0, far=1.0)
        self.D = dr.opaque(mi.Float, dist)
        self.T0, self.dT = (dr.opaque(mi.Float, x) for x in (self.theta0, self.theta_span / R))
        self.P0, self.dP = (dr.opaque(mi.Float, x) for x in (self.phi0, self.phi_span / R))
        self.A0, self.A_inv = dr.opaque(mi.Float, self.alpha0), dr.opaque(mi.Float, 1.0 / self.alpha_span)

    def signature_arrays(self) -> list:
        """The grid's fitted angle and alpha ranges and the eye's distance (``extents``)."""
        return [np.asarray(self.extents, np.float32)]

    def angles(self, p):
        """(theta, phi, alpha) of world points ``p`` (Dr.Jit; theta in [0, 2 pi))."""
        x, y, z = self.local(p)
        radial = dr.sqrt(dr.square(x) + dr.square(y))
        theta = dr.atan2(y, x)
        theta = dr.select(theta < 0, theta + TWO_PI, theta)
        return theta, dr.atan2(radial, z), dr.atan2(radial, self.D - z)

    def project_on(self, p, face=None):
        """(u, v) of world points ``p``: their theta and phi in cells of the grid (``face`` ignored)."""
        theta, phi, _ = self.angles(p)
        dt = theta - self.T0
        dt = dr.select(dt < 0, dt + TWO_PI, dt)
        return dt / self.dT, (phi - self.P0) / self.dP

    def depth(self, p):
        """Depth of world points ``p``: the fraction of the grid's alpha range (0 at alpha_0, 1 at alpha_1)."""
        return (self.angles(p)[2] - self.A0) * self.A_inv

    def depth_per_world(self, p):
        """The depth's change per world length along the light's ray at ``p``: d alpha / d r over the
        alpha range, with d alpha / d r = D sin(phi) / (radial^2 + (D - z)^2) (r: the distance from
        the light, D: the eye's)."""
        x, y, z = self.local(p)
        radial2 = dr.square(x) + dr.square(y)
        r = dr.maximum(dr.norm(p - self.o), 1e-30)
        return self.D * dr.sqrt(radial2) / r / dr.maximum(radial2 + dr.square(self.D - z), 1e-30) * self.A_inv

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the light ray of grid position (u, v): from the light at that theta and phi."""
        theta, phi = self.T0 + u * self.dT, self.P0 + v * self.dP
        s_t, c_t = dr.sincos(theta)
        s_p, c_p = dr.sincos(phi)
        d = self.ez * c_p + (self.ex * c_t + self.ey * s_t) * s_p
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World width of a (theta, phi) cell at points ``p``: distance * sqrt(sin(phi) dtheta dphi)."""
        _, phi, _ = self.angles(p)
        return dr.norm(p - self.o) * dr.sqrt(dr.maximum(dr.sin(phi), 0.0) * self.dT * self.dP)

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light position."""
        return dr.normalize(self.o - p)

    def inside(self, p):
        """Whether world points ``p`` lie in the light's domain: a spot's cone, everywhere for a point light."""
        if self.domain is not None:
            return self.domain(p)
        return dr.full(mi.Bool, True, dr.width(p))


def first_occluded(s_hit, occupancy: str):
    """The first occluded voxel of a column whose first hit is at alpha voxel coordinate ``s_hit``
    (any float): ``floor(s + 1/2)`` when a voxel takes its centre's state (occluded iff its centre
    ``k + 1/2`` lies past the hit), ``floor(s)`` when the hit's own voxel is occluded. Not clamped:
    below 0 the whole column is occluded, at or beyond N none of it."""
    return dr.floor(s_hit + 0.5) if occupancy == "centre" else dr.floor(s_hit)


def voxel_lit(k_test, s_hit, n_alpha, occupancy: str):
    """Margin of the binary test of voxel ``k_test`` (clamped to [-1, N - 1]: the light's side of the
    grid is lit, its far end reads the last voxel) in the column of first hit ``s_hit``: >= 0 lit."""
    k = dr.clip(k_test, -1.0, n_alpha - 1.0)
    first = dr.clip(first_occluded(s_hit, occupancy), 0.0, n_alpha)
    return first - k - 0.5


def voxels(z1: np.ndarray, resolution: int, n_alpha: int, occupancy: str = "centre") -> np.ndarray:
    """The binary grid (phi cell, theta cell, alpha voxel) -> occluded of a VSV map's z1 (numpy)."""
    s = np.asarray(z1, np.float64).reshape(resolution, resolution) * n_alpha
    first = np.floor(s + 0.5) if occupancy == "centre" else np.floor(s)
    first = np.clip(first, 0, n_alpha)
    return np.arange(n_alpha)[None, None, :] >= first[:, :, None]


def grid_bits(resolution: int, n_alpha: int) -> int:
    """Bits of the binary grid: R^2 columns of N voxels (one bit each), as Wyman stores it."""
    return int(resolution) ** 2 * int(n_alpha)
