"""Light views: how a light's shadow map is parameterized.

A view maps world points to continuous map coordinates ``(u, v)`` in texel units (texel
``(i, j)`` covers ``[i, i+1) x [j, j+1)``), gives each point its depth in the view's metric
(world units) and the ray through any map position. Scalars a sweep may change (frame,
extent, resolution) are opaque Dr.Jit values, so one kernel serves every map of a kind.

- ``OrthographicView`` (directional light): depth is the distance along the light
  direction; the map is a square fitted tightly around the receivers in light space, its
  depth range to the whole scene's bounds (every possible caster), as Microsoft's Common Techniques article recommends.
- ``PerspectiveView`` (spot light): rays from the light position, depth is the distance
  along the light's axis; the square map covers the cone.
- Point lights (Brabec et al. 2002): ``ParaboloidView`` (one hemisphere around a main direction, or
  two back to back, the map chosen by the sign of z in light space) and ``CubeView`` (six
  90-degree faces on the world axes). Depth is the Euclidean distance to the light.

A view may have several faces (maps); a point's face comes from its direction alone, so
every point is in exactly one face, and texel ``(face, i, j)`` is stored at
``face * R^2 + j * R + i``.

``texel_world(p)``: the side of a square with the area of the texel's footprint on the plane
through ``p`` perpendicular to the light ray (the square root of the texel's solid angle
times the distance), so "1 texel" means the same thing on every view.
"""
from __future__ import annotations

import copy
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import VIEW_FACES


def light_frame(direction) -> tuple:
    """Right-handed orthonormal (ex, ey, ez) with ez along ``direction``, stable for any axis: numpy
    float64 for a numpy or sequence direction, Dr.Jit (the same construction, differentiable: dsm grad's
    attached light) for a mi.Vector3f."""
    if dr.is_array_v(direction):
        ez = dr.normalize(direction)
        near_z = dr.abs(ez.z) > 0.9
        zero, one = dr.zeros(mi.Float, dr.width(ez)), dr.ones(mi.Float, dr.width(ez))
        ey = dr.normalize(dr.cross(ez, mi.Vector3f(dr.select(near_z, one, zero), zero, dr.select(near_z, zero, one))))
        return dr.cross(ey, ez), ey, ez
    ez = np.asarray(direction, dtype=np.float64)
    ez = ez / np.linalg.norm(ez)
    helper = np.array([1.0, 0.0, 0.0]) if abs(ez[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    ey = np.cross(ez, helper)
    ey /= np.linalg.norm(ey)
    ex = np.cross(ey, ez)
    return ex, ey, ez


def _opaque_vec(v):
    return mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in v))


def frame_value(v):
    """A frame vector as a view holds it: opaque Dr.Jit values of a numpy one; of a Dr.Jit one (attached,
    say) an evaluated copy, so that a component that folds to a constant is not a literal the views'
    ``self.o + ...`` could update in place (Dr.Jit 1.5 did: a directional map's origin took the width of
    its texels, measured)."""
    if not dr.is_array_v(v):
        return _opaque_vec(v)
    out = type(v)(v)
    dr.make_opaque(out)
    return out


def frame_numpy(v) -> np.ndarray:
    """A frame vector's value in numpy float64 (a Dr.Jit one detached, its first lane)."""
    if not dr.is_array_v(v):
        return np.asarray(v, float)
    return np.array([float(dr.detach(c).numpy().ravel()[0]) for c in (v.x, v.y, v.z)])


def _bbox_corners(bbox_min, bbox_max) -> np.ndarray:
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])


class View:
    """Common part: a frame (origin ``o``, axes ``ex``, ``ey``, ``ez``) and the depth metric."""

    kind = "view"
    has_seams = False     # seams between faces or at a rim (paraboloid and cube views)
    # the defaults of what some views set (the readers take every view as one type):
    depth_oracles = True        # the oracles' depth biases apply (a VSV grid, dsm.maps.vsv, has none)
    cascaded = False            # one fit per cascade (dsm.maps.cascades: cascades, spec); built alone, never stacked
    blend = 0.0                 # the cascades' blend band (dsm.maps.cascades); 0: no blended lookup
    light_size = 0.0            # an area light's width, world, for PCSS (dsm.lights.area_surface); 0: none
    light_surface = None        # an area light's surface (dsm.lights.area_surface.Geometry: sample, one_sided), SMRT's
                                # ray targets (dsm.maps.smrt); None: a point, or a light whose surface the view lacks
    exclude = ()                # shapes the map steps over: an area light's own luminaire (dsm.lights.area_surface)
    nearest_scene_depth = 0.0   # the light's distance to the scene's bounds (spot and point views), ndc24's and PCSS's near
    virtual = False             # pages through a page table (dsm.maps.virtual)
    page_table_entries = 0      # a virtual map's page table: one entry per virtual page of every level

    @property
    def faces(self) -> int:
        """Faces (maps) of this view: one fact, types.VIEW_FACES."""
        return VIEW_FACES[self.kind]

    def __init__(self, origin, ex, ey, ez, resolution: int, near: float, far: float, light_size: float = 0.0):
        """The frame (origin and axes: numpy, or Dr.Jit, e.g. attached to a light's parameters) is taken
        here, once: ``o``, ``ex``, ``ey``, ``ez`` in Dr.Jit, ``origin_np``, ``axes_np`` their values;
        ``light_size``: the light's width for PCSS (world; 0: none)."""
        self.resolution = int(resolution)
        self.light_size = float(light_size)
        self.origin_np = frame_numpy(origin)
        self.axes_np = tuple(frame_numpy(a) for a in (ex, ey, ez))
        self.near, self.far = float(near), float(far)
        self.o = frame_value(origin)
        self.ex, self.ey, self.ez = (frame_value(a) for a in (ex, ey, ez))
        self.R = dr.opaque(mi.Float, float(resolution))
        self.R_u = dr.opaque(mi.UInt32, int(resolution))
        self.far_o = dr.opaque(mi.Float, self.far)

    def with_frame(self, origin, ex, ey, ez) -> "View":
        """A new view with this one's fit (resolution, near, far, extent or cone) and the frame given
        here (numpy, or Dr.Jit: dsm grad's attached light), taken at its construction as every view's."""
        view = copy.copy(self)
        View.__init__(view, origin, ex, ey, ez, self.resolution, self.near, self.far, self.light_size)
        return view

    @property
    def depth_range(self) -> float:
        """far - near of the view, in world units (the unit of ``range`` lengths)."""
        return self.far - self.near

    @property
    def n_texels(self) -> int:
        """Texels of all the view's faces together: faces * resolution^2."""
        return self.faces * self.resolution ** 2

    def local(self, p):
        """(x, y, z) of world points ``p`` in the view's frame (origin ``o``, axes ``ex``, ``ey``, ``ez``)."""
        q = p - self.o
        return dr.dot(q, self.ex), dr.dot(q, self.ey), dr.dot(q, self.ez)

    def depth(self, p):
        """Depth of world point ``p`` in the view's metric (world units)."""
        return dr.dot(p - self.o, self.ez)

    def depth_per_world(self, p):
        """The view's depth change per world length along the light's ray at world points ``p``: 1
        where depth is a world length (every view but a VSV grid's)."""
        return dr.ones(mi.Float, dr.width(p))

    def face_of(self, p):
        """The face of world points ``p``: 0 on a single-map view."""
        return dr.zeros(mi.UInt32, dr.width(p))

    def project(self, p):
        """(u, v, face) of world point ``p``: map position in texel units and its face."""
        face = self.face_of(p)
        u, v = self.project_on(p, face)
        return u, v, face

    def plane_hit(self, u, v, p0, n, face=None):
        """(depth, met): where the light's ray through map position (u, v) of ``face`` meets the
        plane (p0, n), in the view's one depth function, and whether it meets it in front of the
        light at a finite point. Where it does not (the plane parallel to the ray, or crossing
        behind the light) the depth is +inf and ``met`` is False; callers choose the fallback."""
        o, d = self.ray_at(u, v, face)
        den = dr.dot(d, n)
        t = dr.dot(p0 - o, n) / dr.select(den != 0, den, 1.0)
        depth = self.depth(o + d * t)
        met = (den != 0) & (t > 0) & dr.isfinite(depth)
        return dr.select(met, depth, dr.inf), met

    def depth_on_plane(self, u, v, p0, n, face=None):
        """Depth where the ray through map position (u, v) of ``face`` meets the plane (p0, n);
        +inf where it does not meet it in front of the light (no NaN ever leaves here)."""
        return self.plane_hit(u, v, p0, n, face)[0]

    def to_square(self, u, v):
        """Map position (texel units) as coordinates in [-1, 1]^2 over the face."""
        return 2.0 * u / self.R - 1.0, 2.0 * v / self.R - 1.0

    def from_square(self, x, y):
        """Coordinates in [-1, 1]^2 as a map position in texel units."""
        h = 0.5 * self.R
        return (x + 1.0) * h, (y + 1.0) * h

    def texel_coords(self, idx):
        """(face, centre u, centre v) of texel indices ``idx``."""
        # at least 1: a stacked view's resolution is gathered per lane (dsm.maps.stacked), and the
        # lanes of a CPU packet past the array's end gather 0, an integer division that traps
        R = dr.maximum(self.R_u, 1)
        RR = R * R
        face, rest = idx // RR, idx % RR
        return face, mi.Float(rest % R) + 0.5, mi.Float(rest // R) + 0.5

    def texel_index(self, face, i, j):
        """(storage index, not stored) of texel (i, j) of ``face`` (i, j within the face): ``face R^2 +
        j R + i``, and None (every texel is stored; a virtual map's page table says otherwise)."""
        return (face * self.R_u + mi.UInt32(j)) * self.R_u + mi.UInt32(i), None

    def texel_rays(self, first: int, count: int) -> mi.Ray3f:
        """Rays through the centres of texels ``first .. first + count - 1`` (face, then row-major)."""
        face, cu, cv = self.texel_coords(dr.arange(mi.UInt32, first, first + count))
        o, d = self.ray_at(cu, cv, face)
        return mi.Ray3f(o, d)

    def texel_bounds(self):
        """Per texel, (near, far) of a map whose texels differ in range (a cascaded map); None: the
        view's own near and far for every texel."""
        return None

    def signature_arrays(self) -> list:
        """What the map's texels depend on beyond the frame, near, far and resolution (float32
        arrays, in a fixed order; a moving camera's frames rebuild the map when they change)."""
        return []

    def frame_signature_arrays(self) -> list:
        """What every page of a paged view depends on beyond the frame, near, far and resolution (a page cache
        keeps its pages while it holds, dsm.experiment.page_cache); elsewhere :meth:`signature_arrays`."""
        return self.signature_arrays()

    def page_keys(self) -> list:
        """Per stored page of a paged view, what names its texels' rays beside :meth:`frame_signature_arrays`
        (hashable; equal keys, equal rays); a view without pages has none."""
        return []

    def with_pages(self, pages) -> "View":
        """A paged view holding only ``pages`` (rows of face, page x, page y) of its own: a view without pages has none."""
        raise TypeError(f"a {self.kind} view has no pages (only a virtual map's view has)")

    def lanes(self, idx):
        """The view as lanes ``idx`` of a build see it: itself (a stacked view, dsm.maps.stacked, gathers its per-lane values)."""
        return self

    def inside(self, p):
        """Whether world points ``p`` are covered by the map: every point on the base view."""
        return dr.full(mi.Bool, True, dr.width(p))

    def seam_distance(self, u, v, face):
        """Distance in texels from map position (u, v) to the nearest seam between faces
        (cube edges, the paraboloids' rim); +inf on a single planar map, which has none."""
        return dr.full(mi.Float, dr.inf, dr.width(u))

    def face_resolution(self, face):
        """Texels a side of faces ``face`` (mi.UInt32): the view's resolution (a virtual punctual map's
        faces differ: dsm.maps.virtual_punctual)."""
        return self.R_u

    def level_of_face(self, faces) -> np.ndarray:
        """The (absolute) level each face of ``faces`` holds (numpy): a virtual map's; elsewhere the face."""
        return np.asarray(faces, int)


MARGIN_TEXELS = 4


class OrthographicView(View):
    """A directional light's map, fitted to the receivers with MARGIN_TEXELS texels to spare on
    each side; a lookup beyond the map (a far normal offset) finds no caster there: lit."""
    kind = "orthographic"

    def __init__(self, direction, receivers_world: np.ndarray, scene_bbox, resolution: int, light_size: float = 0.0):
        """The map of ``direction`` fitted to ``receivers_world`` and, in depth, to ``scene_bbox`` (lo, hi);
        ``light_size``: the light's width for PCSS (world; 0: none)."""
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
        # a margin of MARGIN_TEXELS texels on each side: receivers on the fitted border stay
        # inside in float32, and filter taps and normal-offset lookups near it read real texels
        m = min(MARGIN_TEXELS, resolution // 8)
        # below 8 texels no whole texel can be spared: 1 % of the extent keeps the border
        # receivers inside all the same (the receivers must not depend on the resolution)
        extent *= resolution / (resolution - 2 * m) if m else 1.01
        margin = 0.01 * max(zs.max() - zs.min(), diag, 1e-30)
        cx, cy = 0.5 * (xs.max() + xs.min()), 0.5 * (ys.max() + ys.min())
        z0 = zs.min() - margin
        origin = ex * (cx - extent / 2) + ey * (cy - extent / 2) + ez * z0
        self.extent = float(extent)
        super().__init__(origin, ex, ey, ez, resolution, near=0.0, far=float(zs.max() - z0 + margin),
                         light_size=light_size)
        self.L = dr.opaque(mi.Float, self.extent)

    @classmethod
    def square(cls, direction, x0: float, y0: float, extent: float, scene_bbox, resolution: int) -> "OrthographicView":
        """The single map over a given light-space square (corner (x0, y0) along ``ex``, ``ey``, side
        ``extent``), near and far as a fitted map's (a virtual map's one level is this map)."""
        ex, ey, ez = light_frame(direction)
        zs = _bbox_corners(*scene_bbox) @ ez
        diag = float(np.linalg.norm(np.asarray(scene_bbox[1]) - np.asarray(scene_bbox[0])))
        margin = 0.01 * max(zs.max() - zs.min(), diag, 1e-30)
        z0 = zs.min() - margin
        view = cls.__new__(cls)
        view.extent = float(extent)
        View.__init__(view, ex * x0 + ey * y0 + ez * z0, ex, ey, ez, resolution, near=0.0,
                      far=float(zs.max() - z0 + margin))
        view.L = dr.opaque(mi.Float, view.extent)
        return view

    def turned(self, direction, reach: float) -> "OrthographicView":
        """This map turned to ``direction`` (Dr.Jit, e.g. attached to a light's angle) about the point
        ``reach`` along its central ray from the map plane, its fit (extent, near, far) kept
        (:meth:`View.with_frame`). dsm grad turns a directional map about the point where its central
        ray meets the ground, so the receivers keep their map positions to first order."""
        half = 0.5 * self.extent
        ex0, ey0, ez0 = self.axes_np
        pivot = mi.Point3f(*(float(c) for c in self.origin_np + (ex0 + ey0) * half + ez0 * reach))
        ex, ey, ez = light_frame(direction)
        return self.with_frame(pivot - ez * reach - (ex + ey) * half, ex, ey, ez)

    def signature_arrays(self) -> list:
        """The fitted square's side (the frame holds its corner)."""
        return [np.float32([self.extent])]

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` on the single map (``face`` ignored)."""
        x, y, _ = self.local(p)
        s = self.R / self.L
        return x * s, y * s

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the light ray through map position (u, v): from the map plane along ``ez``."""
        s = self.L / self.R
        o = self.o + self.ex * (u * s) + self.ey * (v * s)
        return o, dr.zeros(mi.Vector3f, dr.width(o)) + self.ez

    def texel_world(self, p):
        """World width of one texel at points ``p``: extent / resolution, the same everywhere."""
        return dr.zeros(mi.Float, dr.width(p)) + self.L / self.R

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light: ``-ez`` everywhere."""
        return dr.zeros(mi.Vector3f, dr.width(p)) - self.ez

    def inside(self, p):
        """Whether world points ``p`` project within the map square [0, R]^2."""
        u, v = self.project_on(p)
        return (u >= 0) & (u <= self.R) & (v >= 0) & (v <= self.R)


class PerspectiveView(View):
    """A spot light's map: a square perspective frustum from the light over its cone; depth along the axis."""
    kind = "perspective"

    def __init__(self, position, axis, cutoff_deg: float, scene_bbox, resolution: int, light_size: float = 0.0):
        """The square map over the cone of half angle ``cutoff_deg`` about ``axis`` from ``position``, its depth
        range to ``scene_bbox`` (lo, hi); ``light_size``: the light's width for PCSS (world; 0: none)."""
        ex, ey, ez = light_frame(axis)
        corners = _bbox_corners(*scene_bbox)
        zs = (corners - np.asarray(position, float)) @ ez
        self.cutoff = float(cutoff_deg)
        self.tan_half = math.tan(math.radians(self.cutoff))
        far = max(float(zs.max()), 1e-30)
        self.nearest_scene_depth = max(float(zs.min()), 0.0)
        super().__init__(position, ex, ey, ez, resolution, near=0.0, far=far * 1.01, light_size=light_size)
        self.T = dr.opaque(mi.Float, self.tan_half)
        self.cos_cut = dr.opaque(mi.Float, math.cos(math.radians(self.cutoff)))

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` through the perspective projection (``face`` ignored)."""
        x, y, z = self.local(p)
        s = self.R * 0.5 / (self.T * z)
        return (x * s + self.R * 0.5), (y * s + self.R * 0.5)

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the ray from the light position through map position (u, v)."""
        a, b = self.to_square(u, v)
        d = dr.normalize(self.ex * (a * self.T) + self.ey * (b * self.T) + self.ez)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World texel size at points ``p``: a planar (gnomonic) texel's footprint, growing with distance."""
        x, y, z = self.local(p)
        return gnomonic_texel(x, y, z, 2.0 * self.T / self.R)

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light position."""
        return dr.normalize(self.o - p)

    def inside(self, p):
        """Whether world points ``p`` lie in front of the light, inside its cone and the map square."""
        x, y, z = self.local(p)
        in_cone = z >= dr.norm(p - self.o) * self.cos_cut
        return (z > 0) & in_cone & (dr.abs(x) <= self.T * z) & (dr.abs(y) <= self.T * z)


def gnomonic_texel(x, y, z, step):
    """World texel size at local point (x, y, z) of a planar (gnomonic) map with ``step`` per texel
    in the tangent plane at unit distance: distance * sqrt(solid angle) = step * z * (1 + a^2 + b^2)^(-1/4)."""
    zz = dr.maximum(z, 1e-30 * dr.norm(mi.Vector3f(x, y, z)))
    r2 = (dr.square(x) + dr.square(y)) / dr.square(zz)
    return step * zz * dr.rsqrt(dr.sqrt(1.0 + r2))


class PointView(View):
    """A point light's view: rays from the light, depth = Euclidean distance to the light."""
    has_seams = True

    def __init__(self, position, axis, scene_bbox, resolution: int):
        ex, ey, ez = light_frame(axis)
        corners = _bbox_corners(*scene_bbox)
        far = float(np.max(np.linalg.norm(corners - np.asarray(position, float), axis=1)))
        lo, hi = (np.asarray(b, float) for b in scene_bbox)
        pos = np.asarray(position, float)
        self.nearest_scene_depth = float(np.linalg.norm(pos - np.clip(pos, lo, hi)))
        super().__init__(position, ex, ey, ez, resolution, near=0.0, far=max(far, 1e-30) * 1.01)

    def depth(self, p):
        """Depth of world points ``p``: the Euclidean distance to the light (world units)."""
        return dr.norm(p - self.o)

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light position."""
        return dr.normalize(self.o - p)


class ParaboloidView(PointView):
    """Paraboloid map(s) of Brabec et al. 2002: direction v -> (vx, vy) / (1 + s vz), s = +1 front, -1 back.

    The texel ray through (x, y) is the direction the paraboloid reflects toward d0:
    ``(2x, 2y, s (1 - x^2 - y^2)) / (1 + x^2 + y^2)`` (Dou et al. 2014, section 3.2). The map is
    conformal (stereographic), so a texel's footprint is square: (2 / R) (|q| + s qz).
    Single paraboloid: the hemisphere z >= 0 around the main direction; dual: z >= 0 is the
    front map, z < 0 the back map, so the denominator |q| + s qz is never below |q|.
    """

    def __init__(self, position, axis, scene_bbox, resolution: int, dual: bool):
        super().__init__(position, axis, scene_bbox, resolution)
        self.dual = bool(dual)
        self.kind = "dual_paraboloid" if dual else "paraboloid"

    def _sign(self, face):
        return dr.select(face == 0, mi.Float(1.0), mi.Float(-1.0))

    def face_of(self, p):
        """The face of world points ``p``: 0 front (z >= 0 in light space), 1 back; 0 on a single paraboloid."""
        if not self.dual:
            return dr.zeros(mi.UInt32, dr.width(p))
        _, _, z = self.local(p)
        return dr.select(z >= 0, mi.UInt32(0), mi.UInt32(1))

    def _den(self, p, face):
        x, y, z = self.local(p)
        r = dr.norm(mi.Vector3f(x, y, z))
        # |q| + s z >= |q| on its own face; a single paraboloid's back half (outside) is clamped
        return x, y, dr.maximum(r + self._sign(face) * z, 1e-7 * r + 1e-30)

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` on face ``face`` (default: each point's own face)."""
        face = self.face_of(p) if face is None else face
        x, y, den = self._den(p, face)
        return self.from_square(x / den, y / den)

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the ray from the light through map position (u, v) of ``face`` (default: front)."""
        x, y = self.to_square(u, v)
        r2 = dr.square(x) + dr.square(y)
        s = self._sign(face) if face is not None else mi.Float(1.0)
        inv = 1.0 / (1.0 + r2)
        d = self.ex * (2.0 * x * inv) + self.ey * (2.0 * y * inv) + self.ez * (s * (1.0 - r2) * inv)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World texel size at points ``p`` on their face: (2 / R) (|q| + s qz), square (conformal map)."""
        _, _, den = self._den(p, self.face_of(p))
        return 2.0 * den / self.R

    def seam_distance(self, u, v, face):
        """Distance in texels from map position (u, v) to the paraboloid's rim (the unit circle of the face)."""
        x, y = self.to_square(u, v)
        return dr.abs(1.0 - dr.sqrt(dr.square(x) + dr.square(y))) * 0.5 * self.R

    def inside(self, p):
        """Whether world points ``p`` are covered: every point when dual, else the front hemisphere z >= 0."""
        if self.dual:
            return super().inside(p)
        _, _, z = self.local(p)
        return z >= 0


# cube faces: +x, -x, +y, -y, +z, -z; (U, V, W) with W the face axis and U x V = W
CUBE_FACES = [((0, 1, 0), (0, 0, 1), (1, 0, 0)), ((0, 0, 1), (0, 1, 0), (-1, 0, 0)),
              ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((1, 0, 0), (0, 0, 1), (0, -1, 0)),
              ((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((0, 1, 0), (1, 0, 0), (0, 0, -1))]


class CubeView(PointView):
    """Six 90-degree perspective faces on the world axes around a point light.

    The face of a point is its direction's major axis; ties (cube edges and corners) go to
    the first of x, y, z, so every direction has exactly one face, and on an edge the
    projection lands on that face's border (u or v = 0 or R), never outside it.
    """
    kind = "cube"

    def __init__(self, position, scene_bbox, resolution: int):
        super().__init__(position, (0, 0, 1), scene_bbox, resolution)
        tab = np.asarray(CUBE_FACES, float)        # (6, 3 vectors, 3 coords)
        self.U, self.V, self.W = (mi.Vector3f(*(tab[:, k, c] for c in range(3))) for k in range(3))

    def face_axes(self, face):
        """The axes of faces ``face`` (per receiver): the map's u and v axes and W, the face's outward axis."""
        return (dr.gather(mi.Vector3f, self.U, face), dr.gather(mi.Vector3f, self.V, face),
                dr.gather(mi.Vector3f, self.W, face))

    def face_of(self, p):
        """The face of world points ``p``: 2 * major axis + 1 if negative (ties go to x, then y, then z)."""
        q = p - self.o
        ax, ay, az = dr.abs(q.x), dr.abs(q.y), dr.abs(q.z)
        use_x = (ax >= ay) & (ax >= az)
        use_y = ~use_x & (ay >= az)
        neg = dr.select(use_x, q.x < 0, dr.select(use_y, q.y < 0, q.z < 0))
        axis = dr.select(use_x, mi.UInt32(0), dr.select(use_y, mi.UInt32(1), mi.UInt32(2)))
        return 2 * axis + dr.select(neg, mi.UInt32(1), mi.UInt32(0))

    def _local(self, p, face):
        U, V, W = self.face_axes(face)
        q = p - self.o
        z = dr.dot(q, W)
        return dr.dot(q, U), dr.dot(q, V), dr.maximum(z, 1e-30 * dr.norm(q) + 1e-38)

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` on cube face ``face`` (default: each point's own face)."""
        face = self.face_of(p) if face is None else face
        x, y, z = self._local(p, face)
        return self.from_square(x / z, y / z)

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the ray from the light through map position (u, v) of ``face`` (default: +x)."""
        face = dr.zeros(mi.UInt32, dr.width(u)) if face is None else face
        U, V, W = self.face_axes(face)
        a, b = self.to_square(u, v)
        d = dr.normalize(U * a + V * b + W)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World texel size at points ``p`` on their cube face (a gnomonic footprint, growing with distance)."""
        x, y, z = self._local(p, self.face_of(p))
        return gnomonic_texel(x, y, z, 2.0 / self.R)

    def seam_distance(self, u, v, face):
        """Distance in texels from map position (u, v) to the nearest edge of its cube face."""
        return dr.minimum(dr.minimum(u, self.R - u), dr.minimum(v, self.R - v))
