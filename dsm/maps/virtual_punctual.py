"""Virtual shadow maps of spot and point lights: a perspective page table over a spot's square frustum,
or one per cube face around a point light, their levels halving the resolution, each receiver's level
from its camera pixel's footprint seen from the light (Blender EEVEE's punctual rule), pages tagged by
the receivers. A point light's receiver reads the cube face its direction selects (its major axis).

Level ``k`` (``first_level .. last_level``, EEVEE 0 to ``SHADOW_TILEMAP_LOD`` = 5) is the spot's
perspective map at ``resolution / 2^k`` texels a side (EEVEE: ``SHADOW_MAP_MAX_RES`` = 8192 at
level 0), cut into pages of ``page_size^2`` (``resolution / page_size / 2^k`` pages a side). Only the
pages some receiver tags are ray-cast; a lookup reads a texel through the page table, and a texel of
a page no receiver tagged reads as no caster (the far bound), as the directional virtual map's.

**A receiver's level** (re-derived from the description of ``shadow_punctual_pixel_ratio``,
eevee_shadow_tilemap_lib.glsl; Blender is GPL, no code copied): the camera pixel's radius ``r``
(its diagonal on the camera's unit plane, ``ShadowModule::screen_pixel_radius``) times
``2^lod_bias`` and the receiver's view depth ``z_cam`` is its footprint in the world; floored by
``lod_min`` where positive (world metres); divided by the receiver's largest-axis distance to the
light ``max(|x|, |y|, |z|)`` (light frame) it is a length on the light's unit plane, floored by
``-lod_min`` where negative; against the level-0 texel's radius there (EEVEE's ``2 sqrt 2 /
SHADOW_MAP_MAX_RES`` on a cube face of half width 1: here ``sqrt 2 x 2 T / R``, ``T`` the
frustum's half width, 1 on a cube), the level is ``floor(clamp(log2(footprint / texel radius), first_level,
last_level))``: the finest level whose texel is at least the footprint.
"""
from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import VirtualSpec
from ..scenes.camera import Camera
from .views import CubeView, PerspectiveView, gnomonic_texel
from .virtual import pages_subset, physical_texel_coords, tagged_pages

NO_PAGE = 0xFFFFFFFF


def film_pixel_radius(camera: Camera) -> float:
    """A camera pixel's diagonal on the camera's unit plane (EEVEE's screen_pixel_radius, eevee_shadow.cc)."""
    return math.hypot(2.0 * camera.tan_x / camera.width, 2.0 * camera.tan_y / camera.height)


def level_resolution(spec: VirtualSpec, level) -> np.ndarray:
    """Texels a side of absolute level ``level``: resolution / 2^level."""
    return spec.resolution // (2 ** np.asarray(level, np.int64))


class PunctualPages:
    """What a spot's and a point light's virtual maps share: faces of per-face resolution through one page
    table, the punctual level rule, the tagging. A subclass calls :meth:`_setup` (levels, per-face arrays)
    and :meth:`_pages`, and gives ``largest_axis`` and ``cube_face``; it is mixed in before its view class."""
    virtual = True

    def _setup(self, spec: VirtualSpec, camera: Camera, scale: float, half_width: float, cube_faces: int):
        """Levels, per-face resolutions, page table bases and the rule's constants (float64 here)."""
        self.spec, self.camera, self.scale = spec, camera, float(scale)
        self.levels = np.arange(spec.first_level, spec.last_level + 1)
        self.cube_faces = cube_faces
        self.face_level_np = np.tile(self.levels, cube_faces)            # face f: cube face f // L, level f % L
        self.res_np = level_resolution(spec, self.face_level_np)
        self.page_size = spec.page_size
        self.sides_np = self.res_np // spec.page_size
        self.base_np = np.concatenate([[0], np.cumsum(self.sides_np ** 2)[:-1]]).astype(np.int64)
        self.pixel_radius = film_pixel_radius(camera) * 2.0 ** spec.lod_bias
        self.texel_radius = math.sqrt(2.0) * 2.0 * half_width / spec.resolution
        self.lod_min_world = spec.lod_min * 100.0 / spec.unit_cm * self.scale if spec.lod_min > 0 else 0.0
        self.lod_min_plane = -spec.lod_min if spec.lod_min < 0 else 0.0
        self.Rf = mi.Float(self.res_np.astype(np.float32))
        self.Ru = mi.UInt32(self.res_np.astype(np.uint32))
        self.Sf = mi.UInt32(self.sides_np.astype(np.uint32))
        self.Bf = mi.UInt32(self.base_np.astype(np.uint32))
        self.cam_o = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.origin))
        self.cam_f = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.forward))
        self.P_u = dr.opaque(mi.UInt32, self.page_size)
        self.PP_u = dr.opaque(mi.UInt32, self.page_size ** 2)

    def _pages(self, receivers_world):
        """Tag the receivers' pages and build the page table (a first page stands in where none is tagged)."""
        pts = np.asarray(receivers_world, float).reshape(-1, 3)
        self.pages = self._tag(pts)
        if not len(self.pages):       # nothing to tag (no receiver in the light's domain)
            self.pages = np.zeros((1, 3), int)
        if len(self.pages) > self.spec.max_pages:
            raise ValueError(f"the virtual shadow map tags {len(self.pages)} pages, more than its pool "
                             f"(map.virtual.max_pages = {self.spec.max_pages}): raise max_pages or lod_bias")
        self.build_page_table()

    def _tag(self, pts: np.ndarray) -> np.ndarray:
        """The pages (face, page x, page y) the receivers ``pts`` inside the view tag: their level's
        page, and the neighbour across an edge within ``border`` of a page; sorted by face, row, column."""
        return tagged_pages(self, pts, lambda f: self.sides_np[f], self.spec.border)

    def build_page_table(self):
        """The physical page of each virtual page (NO_PAGE: not tagged) and each physical page's place."""
        table = np.full(self.page_table_entries, NO_PAGE, np.uint32)
        pg = self.pages
        at = self.base_np[pg[:, 0]] + pg[:, 2] * self.sides_np[pg[:, 0]] + pg[:, 1]
        table[at] = np.arange(len(pg), dtype=np.uint32)
        self.table = mi.UInt32(table)
        self.page_face = mi.UInt32(pg[:, 0].astype(np.uint32))
        self.page_x = mi.UInt32(pg[:, 1].astype(np.uint32))
        self.page_y = mi.UInt32(pg[:, 2].astype(np.uint32))

    # ------------------------------------------------------------ what the kit reads of a view
    @property
    def faces(self) -> int:
        """Faces of the view: one per level (per cube face and level on a point light)."""
        return len(self.face_level_np)

    @property
    def n_texels(self) -> int:
        """Physical texels: the tagged pages times page_size^2 (what the build casts and stores)."""
        return len(self.pages) * self.page_size ** 2

    @property
    def page_table_entries(self) -> int:
        """Entries of the page table: every virtual page of every face (tagged or not)."""
        return int((self.sides_np ** 2).sum())

    @property
    def n_pages(self) -> int:
        """Pages tagged (each one built)."""
        return len(self.pages)

    def level_ratio_log2(self, p):
        """log2(footprint / level-0 texel radius) at world points ``p``, before the clamp (float32)."""
        z_cam = dr.dot(p - self.cam_o, self.cam_f)
        foot = dr.maximum(self.pixel_radius * z_cam, self.lod_min_world)
        foot = dr.maximum(foot / self.largest_axis(p), self.lod_min_plane)
        return dr.log2(foot / self.texel_radius)

    def level_index(self, p):
        """The level (index from first_level) of world points ``p`` by EEVEE's punctual rule."""
        lvl = dr.floor(dr.clip(self.level_ratio_log2(p), float(self.spec.first_level), float(self.spec.last_level)))
        return mi.UInt32(mi.Int32(lvl) - self.spec.first_level)

    def face_of(self, p):
        """The face of world points ``p``: cube face x levels + level (a spot: its level)."""
        return self.cube_face(p) * len(self.levels) + self.level_index(p)

    def texel_coords(self, idx):
        """(face, centre u, centre v) of physical texels ``idx``: page ``idx // P^2``, its texel ``idx % P^2``."""
        return physical_texel_coords(self, idx)

    def texel_index(self, face, i, j):
        """(physical index, not stored) of texel (i, j) of ``face`` (clamped to it) through the page table."""
        top = mi.Int32(dr.gather(mi.UInt32, self.Ru, face)) - 1
        iu, ju = mi.UInt32(dr.clip(mi.Int32(i), 0, top)), mi.UInt32(dr.clip(mi.Int32(j), 0, top))
        S = dr.gather(mi.UInt32, self.Sf, face)
        vpage = dr.gather(mi.UInt32, self.Bf, face) + (ju // self.P_u) * S + iu // self.P_u
        page = dr.gather(mi.UInt32, self.table, vpage)
        absent = page == NO_PAGE
        idx = page * self.PP_u + (ju % self.P_u) * self.P_u + iu % self.P_u
        return dr.select(absent, 0, idx), absent

    def face_resolution(self, face):
        """Texels a side of faces ``face``: resolution / 2^level."""
        return dr.gather(mi.UInt32, self.Ru, face)

    def to_square(self, u, v):
        """Not defined on a view whose faces differ in resolution: :meth:`ray_at` takes the face."""
        raise NotImplementedError("a virtual punctual map's square coordinates need the face: use ray_at(u, v, face)")

    def signature_arrays(self) -> list:
        """The tagged pages (a moving camera rebuilds when they change)."""
        return [np.asarray(self.pages, np.float32).ravel()]

    def frame_signature_arrays(self) -> list:
        """Nothing beyond the frame: a page's rays depend on the light's frame, the cone and its face alone."""
        return []

    def page_keys(self) -> list:
        """Per tagged page: (face, page x, page y): equal keys, equal rays in views of one frame."""
        return [(int(f), int(x), int(y)) for f, x, y in self.pages]

    def with_pages(self, pages):
        """This view holding only ``pages`` (rows of face, page x, page y, tagged here): its page table rebuilt."""
        return pages_subset(self, pages)

    def level_of_face(self, faces) -> np.ndarray:
        """The level of each face of ``faces`` (a point light's: of its cube face's levels)."""
        return self.face_level_np[np.asarray(faces, int)]

    def level_pages(self) -> dict:
        """{level: pages tagged} for the levels with pages (every cube face together)."""
        lv, counts = np.unique(self.face_level_np[self.pages[:, 0]], return_counts=True)
        return {int(a): int(c) for a, c in zip(lv, counts)}


class VirtualSpotView(PunctualPages, PerspectiveView):
    """A spot light's virtual shadow map: one face per level of a perspective page table, pages tagged by receivers."""

    def __init__(self, position, axis, cutoff_deg: float, spec: VirtualSpec, camera: Camera, receivers_world,
                 scene_bbox, scale: float = 1.0):
        t_start = time.perf_counter()
        PerspectiveView.__init__(self, position, axis, cutoff_deg, scene_bbox, spec.resolution)
        self._setup(spec, camera, scale, self.tan_half, 1)
        self._pages(receivers_world)
        self.fit_ms = (time.perf_counter() - t_start) * 1e3

    def largest_axis(self, p):
        """The largest of |x|, |y|, |z| of world points ``p`` in the light's frame."""
        x, y, z = self.local(p)
        return dr.maximum(dr.maximum(dr.abs(x), dr.abs(y)), dr.abs(z))

    def cube_face(self, p):
        """0: a spot has one face per level."""
        return dr.zeros(mi.UInt32, dr.width(p))

    def project_on(self, p, face=None):
        """(u, v) in texels of level ``face`` of world points ``p`` (default: each point's own level)."""
        face = self.face_of(p) if face is None else face
        Rk = dr.gather(mi.Float, self.Rf, face)
        x, y, z = self.local(p)
        s = Rk * 0.5 / (self.T * z)
        return x * s + Rk * 0.5, y * s + Rk * 0.5

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the ray from the light through (u, v) of level ``face`` (default: the first)."""
        face = dr.zeros(mi.UInt32, dr.width(u)) if face is None else face
        Rk = dr.gather(mi.Float, self.Rf, face)
        a, b = 2.0 * u / Rk - 1.0, 2.0 * v / Rk - 1.0
        d = dr.normalize(self.ex * (a * self.T) + self.ey * (b * self.T) + self.ez)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World texel size at points ``p`` in their own level: a planar texel's footprint."""
        x, y, z = self.local(p)
        Rk = dr.gather(mi.Float, self.Rf, self.face_of(p))
        return gnomonic_texel(x, y, z, 2.0 * self.T / Rk)


class VirtualCubeView(PunctualPages, CubeView):
    """A point light's virtual shadow map: six cube faces x levels, each receiver on its direction's face."""

    def __init__(self, position, spec: VirtualSpec, camera: Camera, receivers_world, scene_bbox, scale: float = 1.0):
        t_start = time.perf_counter()
        CubeView.__init__(self, position, scene_bbox, spec.resolution)
        self._setup(spec, camera, scale, 1.0, 6)
        self._pages(receivers_world)
        self.fit_ms = (time.perf_counter() - t_start) * 1e3

    def largest_axis(self, p):
        """The largest of |x|, |y|, |z| of world points ``p`` about the light (the cube's axes)."""
        q = p - self.o
        return dr.maximum(dr.maximum(dr.abs(q.x), dr.abs(q.y)), dr.abs(q.z))

    def cube_face(self, p):
        """The cube face of world points ``p``: their direction's major axis (CubeView's choice)."""
        return CubeView.face_of(self, p)

    def face_axes(self, face):
        """The axes (U, V, W) of faces ``face`` (cube face x levels + level): their cube face's."""
        return CubeView.face_axes(self, face // len(self.levels))

    def project_on(self, p, face=None):
        """(u, v) in texels of ``face`` of world points ``p`` (default: each point's own face and level)."""
        face = self.face_of(p) if face is None else face
        Rk = dr.gather(mi.Float, self.Rf, face)
        x, y, z = self._local(p, face)
        return (x / z + 1.0) * (0.5 * Rk), (y / z + 1.0) * (0.5 * Rk)

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the ray from the light through (u, v) of ``face`` (default: +x, the first level)."""
        face = dr.zeros(mi.UInt32, dr.width(u)) if face is None else face
        Rk = dr.gather(mi.Float, self.Rf, face)
        U, V, W = self.face_axes(face)
        d = dr.normalize(U * (2.0 * u / Rk - 1.0) + V * (2.0 * v / Rk - 1.0) + W)
        return dr.zeros(mi.Point3f, dr.width(d)) + self.o, d

    def texel_world(self, p):
        """World texel size at points ``p`` on their cube face, in their level."""
        face = self.face_of(p)
        x, y, z = self._local(p, face)
        return gnomonic_texel(x, y, z, 2.0 / dr.gather(mi.Float, self.Rf, face))

    def seam_distance(self, u, v, face):
        """Distance in texels of ``face`` from (u, v) to the nearest edge of its cube face."""
        Rk = dr.gather(mi.Float, self.Rf, face)
        return dr.minimum(dr.minimum(u, Rk - u), dr.minimum(v, Rk - v))


def cube_view(light, spec: VirtualSpec, receivers_world, bbox, sensor, scale: float = 1.0) -> VirtualCubeView:
    """The virtual cube view of a point light for the camera ``sensor`` (a Mitsuba sensor or a Camera)."""
    camera = sensor if isinstance(sensor, Camera) else Camera.from_sensor(sensor)
    return VirtualCubeView(light.position, spec, camera, receivers_world, bbox, scale)


def spot_view(light, spec: VirtualSpec, receivers_world, bbox, sensor, scale: float = 1.0) -> VirtualSpotView:
    """The virtual view of a spot light for the camera ``sensor`` (a Mitsuba sensor or a Camera)."""
    camera = sensor if isinstance(sensor, Camera) else Camera.from_sensor(sensor)
    axis = light.direction if light.direction is not None else np.subtract(light.target, light.position)
    return VirtualSpotView(light.position, axis, light.cutoff, spec, camera, receivers_world, bbox, scale)
