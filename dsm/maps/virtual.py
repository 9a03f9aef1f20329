"""Virtual shadow maps of directional lights: clipmap levels around the camera, pages tagged by
the receivers, each receiver looked up in its own level (Unreal Engine 5's and Blender EEVEE's).

A virtual view is one view of ``N`` faces, one face per clipmap level (absolute levels
``first_level .. last_level``), each an orthographic map of ``resolution^2`` virtual texels cut
into pages of ``page_size^2``. Only the pages some receiver tags are ray-cast (stored one after
another: the physical pages); a lookup reads a texel through the page table and a texel of a page
no receiver tagged reads as beyond the map (no caster: the far bound).

- **Levels.** Level ``l`` is ``width(l)`` wide (UE5: its radius ``2^(l+1)`` cm, the level four radii
  wide; EEVEE: ``2^l`` Blender units), centred on the camera's light-space position rounded to a
  grid (UE5: the radius; EEVEE: one page). ``unit_cm`` says how many centimetres one scene unit
  is (times the scene's ``scale``, so a scaled scene keeps its levels).
- **A receiver's level** from its distance ``d`` to the camera (scene units; ``C``: :func:`level_constant`):
  ``footprint`` (UE5) ``floor(log2 d + C)``, ``C = log2(cm per unit) + max(0, lod_bias +
  log2(0.5 R tan(fov_x / 2) / W))``: the finest level whose texel is wider than the camera pixel's
  footprint at ``d`` (``2 d tan(fov_x / 2) / W``) times ``2^lod_bias``, never finer than the level
  whose radius covers ``d``; ``distance`` (EEVEE) ``ceil(log2(2 d n) + lod_bias)`` in metres,
  ``n = T / (T - 1.0001)`` (``T`` pages a side): the level that covers ``d`` with one page to
  spare. Both are clamped to ``[first_level, last_level]``.
- **Tagging.** Each receiver tags the page under its position in its level, and the neighbour
  across an edge when it lies within ``border`` of a page of that edge (UE5's page dilation).
- **The build** casts the tagged pages in one pass: physical texel ``k`` is page ``k // P^2``, the
  texel ``k % P^2`` in it, and its ray is the whole map's formula at its global texel (level,
  ``i``, ``j``): the same bits as a whole level built alone.

One depth function for the whole view (distance along the light from the scene's near plane) and
one near and far (the scene's bounds along the light, with a margin), as the single map has.
"""
from __future__ import annotations

import copy
import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import VirtualSpec
from ..scenes.camera import Camera
from .views import View, light_frame

NO_PAGE = 0xFFFFFFFF
# shadow_directional_level_fractional (eevee_shadow_tilemap_lib.glsl): one tile hidden to hide the moving transition
EEVEE_NARROWING = 1.0001


def pages_per_side(spec: VirtualSpec) -> int:
    """Pages along one side of a level: resolution / page_size."""
    return spec.resolution // spec.page_size


def level_constant(spec: VirtualSpec, camera: Camera, scale: float = 1.0) -> float:
    """``C`` of a receiver's level, ``floor(log2 d + C)`` (footprint) or ``ceil(log2 d + C)`` (distance),
    ``d`` its distance to the camera in scene units (float64)."""
    if spec.rule == "footprint":
        # UE5 (VirtualShadowMapClipmap.cpp): ResolutionLodBias = max(0, bias + log2(LodScale)),
        # LodScale = 0.5 / ProjectionScaleX * 16384 / ViewWidth, and ProjectionScaleX = 1 / tan(fov_x / 2)
        lod_scale = 0.5 * camera.tan_x * spec.resolution / camera.width
        return math.log2(spec.unit_cm / scale) + max(0.0, spec.lod_bias + math.log2(lod_scale))
    tiles = pages_per_side(spec)
    narrowing = tiles / (tiles - EEVEE_NARROWING)
    return math.log2(spec.unit_cm / (100.0 * scale)) + math.log2(2.0 * narrowing) + spec.lod_bias


def level_width(spec: VirtualSpec, level, scale: float = 1.0):
    """World width (scene units) of absolute level ``level``: UE5 ``2^(l+3)`` cm, EEVEE ``2^l`` m."""
    return spec.level_width(np.asarray(level, float), scale)


def level_snap(spec: VirtualSpec, width):
    """The grid a level's centre is rounded to: UE5 its radius (a quarter of its width), EEVEE one page."""
    return np.asarray(width, float) / (4.0 if spec.rule == "footprint" else pages_per_side(spec))


class VirtualView(View):
    """A directional light's virtual shadow map: one face per clipmap level, pages tagged by the receivers."""
    kind = "orthographic"
    cascaded = True
    virtual = True

    def __init__(self, direction, spec: VirtualSpec, camera: Camera, receivers_world, scene_bbox,
                 scale: float = 1.0, all_pages: bool = False):
        t_start = time.perf_counter()
        ex, ey, ez = light_frame(direction)
        self.spec, self.camera, self.scale = spec, camera, float(scale)
        self.cascades = spec.count
        self.page_size, self.pages_side = spec.page_size, pages_per_side(spec)
        self.C = level_constant(spec, camera, scale)
        lo, hi = (np.asarray(b, float) for b in scene_bbox)
        corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
        zs = corners @ ez
        margin = 0.01 * max(zs.max() - zs.min(), float(np.linalg.norm(hi - lo)), 1e-30)
        z0 = zs.min() - margin      # as OrthographicView: the scene's bounds along the light
        self.levels = np.arange(spec.first_level, spec.last_level + 1)
        self.extents = level_width(spec, self.levels, scale)
        snap = level_snap(spec, self.extents)
        cam = np.asarray(camera.origin, float)
        self.rects = []
        origins = []
        for w, s in zip(self.extents, snap):
            x0 = float(np.round(cam @ ex / s) * s - w / 2)
            y0 = float(np.round(cam @ ey / s) * s - w / 2)
            self.rects.append((x0, y0, float(w)))
            origins.append(ex * x0 + ey * y0 + ez * z0)
        self.origins = np.array(origins)
        View.__init__(self, origins[0], ex, ey, ez, spec.resolution, near=0.0, far=float(zs.max() - z0 + margin))
        self._place()
        pts = np.asarray(receivers_world, float).reshape(-1, 3)
        t_jit = time.perf_counter()
        self.pages = self._tag(pts, all_pages)       # (n, 3) int: face, page x, page y (sorted)
        if not len(self.pages):
            self.pages = self._no_page(len(pts))
        t_start += time.perf_counter() - t_jit          # fit_ms: the host's work, not the tagging kernel
        if len(self.pages) > spec.max_pages:
            raise ValueError(f"the virtual shadow map tags {len(self.pages)} pages, more than its pool "
                             f"(map.virtual.max_pages = {spec.max_pages}): raise max_pages or lod_bias")
        self.build_page_table()
        self.fit_ms = (time.perf_counter() - t_start) * 1e3

    # ------------------------------------------------------------ set-up
    def _place(self):
        """The Dr.Jit values the kernels read (opaque: one kernel serves every map of this kind)."""
        if self.cascades == 1:      # one level: the single orthographic map's scalars, bit for bit
            self.L = dr.opaque(mi.Float, float(self.extents[0]))
            self.A = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in self.origins[0]))
        else:
            self.L = mi.Float(np.float32(self.extents))
            self.A = mi.Vector3f(*(mi.Float(self.origins[:, c].astype(np.float32)) for c in range(3)))
        self.cam_o = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in self.camera.origin))
        self.C_o = dr.opaque(mi.Float, self.C)
        self.P_u = dr.opaque(mi.UInt32, self.page_size)
        self.PP_u = dr.opaque(mi.UInt32, self.page_size ** 2)
        self.S_u = dr.opaque(mi.UInt32, self.pages_side)

    def _tag(self, pts: np.ndarray, all_pages: bool) -> np.ndarray:
        """The pages the receivers ``pts`` tag (their level's page, and the neighbour across an edge
        within ``border`` of a page), sorted by level, row and column; ``all_pages``: every page of
        the levels they read."""
        S = self.pages_side
        tagged = tagged_pages(self, pts, lambda f: np.full_like(f, S), self.spec.border)
        if all_pages:
            g = np.arange(S)
            out = [(k, x, y) for k in np.unique(tagged[:, 0]) for y in g for x in g]
            return np.array(out, int).reshape(-1, 3)
        return tagged

    def _no_page(self, n_receivers: int) -> np.ndarray:
        """The pages of a map no receiver tagged: none lit (a sun from below) is an empty case, as
        an orthographic map's, so its first level's first page stands in (a map of no page cannot be
        built); receivers outside every level are a range that cannot see them, named."""
        if n_receivers:
            spec = self.spec
            raise ValueError(f"none of the {n_receivers} receivers lies inside the virtual map's levels "
                             f"{spec.first_level} to {spec.last_level} ({self.extents[0]:.3g} to {self.extents[-1]:.3g} "
                             f"scene units wide about the camera; map.virtual.first_level, last_level or levels, and "
                             f"unit_cm = {spec.unit_cm:g} set them): raise last_level (at most 60) or lower unit_cm")
        return np.zeros((1, 3), int)

    def build_page_table(self):
        """The physical page of each virtual page (NO_PAGE: not tagged) and each physical page's place."""
        S = self.pages_side
        table = np.full(self.cascades * S * S, NO_PAGE, np.uint32)
        pg = self.pages
        table[(pg[:, 0] * S + pg[:, 2]) * S + pg[:, 1]] = np.arange(len(pg), dtype=np.uint32)
        self.table = mi.UInt32(table)
        self.page_face = mi.UInt32(pg[:, 0].astype(np.uint32))
        self.page_x = mi.UInt32(pg[:, 1].astype(np.uint32))
        self.page_y = mi.UInt32(pg[:, 2].astype(np.uint32))

    def _per_face(self, face):
        if self.cascades == 1:
            return self.A, self.L
        return dr.gather(mi.Vector3f, self.A, face), dr.gather(mi.Float, self.L, face)

    # ------------------------------------------------------------ what the kit reads of a view
    @property
    def faces(self) -> int:
        """Faces of the view: one per clipmap level."""
        return self.cascades

    @property
    def n_texels(self) -> int:
        """Physical texels: the tagged pages times page_size^2 (what the build casts and stores)."""
        return len(self.pages) * self.page_size ** 2

    @property
    def page_table_entries(self) -> int:
        """Entries of the page table: every virtual page of every level (tagged or not)."""
        return self.faces * self.pages_side ** 2

    @property
    def n_pages(self) -> int:
        """Pages tagged (each one built)."""
        return len(self.pages)

    def face_of(self, p):
        """The level (face: absolute level - first_level) of world points ``p`` from their distance to the camera."""
        x = dr.log2(dr.norm(p - self.cam_o)) + self.C_o
        lvl = dr.floor(x) if self.spec.rule == "footprint" else dr.ceil(x)
        lvl = dr.clip(lvl, float(self.spec.first_level), float(self.spec.last_level))
        return mi.UInt32(mi.Int32(lvl) - self.spec.first_level)

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` on level ``face`` (default: each point's own level)."""
        face = self.face_of(p) if face is None else face
        A, L = self._per_face(face)
        q = p - A
        s = self.R / L
        return dr.dot(q, self.ex) * s, dr.dot(q, self.ey) * s

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the light ray through (u, v) of level ``face`` (default 0): along ``ez``."""
        face = dr.zeros(mi.UInt32, dr.width(u)) if face is None else face
        A, L = self._per_face(face)
        s = L / self.R
        o = A + self.ex * (u * s) + self.ey * (v * s)
        return o, dr.zeros(mi.Vector3f, dr.width(o)) + self.ez

    def texel_coords(self, idx):
        """(level, centre u, centre v) of physical texels ``idx``: page ``idx // P^2``, texel ``idx % P^2`` in it."""
        return physical_texel_coords(self, idx)

    def texel_index(self, face, i, j):
        """(physical index, not stored) of virtual texel (i, j) of level ``face``: through the page table."""
        iu, ju = mi.UInt32(i), mi.UInt32(j)
        vpage = (face * self.S_u + ju // self.P_u) * self.S_u + iu // self.P_u
        page = dr.gather(mi.UInt32, self.table, vpage)
        absent = page == NO_PAGE
        idx = page * self.PP_u + (ju % self.P_u) * self.P_u + iu % self.P_u
        return dr.select(absent, 0, idx), absent

    def texel_world(self, p):
        """World width of one texel at points ``p``: their level's width / resolution."""
        _, L = self._per_face(self.face_of(p))
        return dr.zeros(mi.Float, dr.width(p)) + L / self.R

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light: ``-ez`` everywhere."""
        return dr.zeros(mi.Vector3f, dr.width(p)) - self.ez

    def inside(self, p):
        """Whether world points ``p`` project within their level's square (beyond the last level's: not)."""
        u, v = self.project_on(p)
        return (u >= 0) & (u <= self.R) & (v >= 0) & (v <= self.R)

    def signature_arrays(self) -> list:
        """Each level's width and rectangle, and the tagged pages (a moving camera rebuilds when they change)."""
        return [np.asarray(self.extents, np.float32), np.asarray(self.rects, np.float32),
                np.asarray(self.pages, np.float32).ravel()]

    def frame_signature_arrays(self) -> list:
        """Each level's width: a page's rays depend on it, on the frame (the first level's origin, the depth's)
        and on its own level's rectangle, which :meth:`page_keys` names."""
        return [np.asarray(self.extents, np.float32)]

    def page_keys(self) -> list:
        """Per tagged page: (face, page x, page y, its level's rectangle x0, y0, width): equal keys, equal rays
        in views of equal :meth:`frame_signature_arrays` (a level panned with the camera names new pages)."""
        return [(int(f), int(x), int(y), *self.rects[int(f)]) for f, x, y in self.pages]

    def with_pages(self, pages) -> "VirtualView":
        """This view holding only ``pages`` (rows of face, page x, page y, tagged here): its page table rebuilt."""
        return pages_subset(self, pages)

    def texel_size(self, k: int) -> float:
        """World width of one texel of level face ``k`` (float64)."""
        return float(self.extents[k]) / self.resolution

    def distance_range(self, k: int) -> tuple:
        """[near, far) of camera distance (scene units) whose receivers the rule puts in face ``k``
        (unclamped; the first level from 0, the last to infinity)."""
        lvl = int(self.levels[k])
        lo, hi = (2.0 ** (lvl - self.C), 2.0 ** (lvl + 1 - self.C)) if self.spec.rule == "footprint" \
            else (2.0 ** (lvl - 1 - self.C), 2.0 ** (lvl - self.C))
        return (0.0 if k == 0 else lo), (math.inf if k == self.cascades - 1 else hi)

    def level_of_face(self, faces) -> np.ndarray:
        """The absolute level of each face of ``faces`` (one face per level)."""
        return self.levels[np.asarray(faces, int)]

    def level_pages(self) -> dict:
        """{absolute level: pages tagged} for the levels with pages."""
        faces, counts = np.unique(self.pages[:, 0], return_counts=True) if len(self.pages) else ((), ())
        return {int(self.levels[f]): int(c) for f, c in zip(faces, counts)}

    def describe(self) -> list:
        """Per level with tagged pages: its distance range, width, texel size, near and far (cascades.csv's rows)."""
        out = []
        for k in sorted({int(f) for f in self.pages[:, 0]}):
            lo, hi = self.distance_range(k)
            out.append({"cascade": int(self.levels[k]), "face": k, "split_near": lo, "split_far": hi,
                        "extent": float(self.extents[k]), "texel_size": self.texel_size(k),
                        "near": self.near, "far": self.far})
        return out


def make_view(light, spec: VirtualSpec, receivers_world, bbox, sensor, scale: float = 1.0) -> VirtualView:
    """The virtual view of a directional light for the camera ``sensor`` (a Mitsuba sensor or a Camera)."""
    camera = sensor if isinstance(sensor, Camera) else Camera.from_sensor(sensor)
    return VirtualView(light.direction, spec, camera, receivers_world, bbox, scale)



def tagged_pages(view, pts: np.ndarray, pages_side, border: float) -> np.ndarray:
    """The pages (face, page x, page y) that world points ``pts`` inside a virtual ``view`` tag: each
    point's own page, and the neighbour across an edge within ``border`` (pages) of it; ``pages_side(f)``:
    pages a side of faces ``f``. Sorted by face, row and column."""
    if not len(pts):
        return np.zeros((0, 3), int)
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    face = view.face_of(p)
    u, v = view.project_on(p, face)
    ok = view.inside(p)
    dr.eval(face, u, v, ok)
    ok = np.asarray(ok.numpy(), bool)
    f = np.asarray(face.numpy(), int)[ok]
    S, P = pages_side(f), view.page_size
    fu, fv = np.asarray(u.numpy(), float)[ok] / P, np.asarray(v.numpy(), float)[ok] / P
    px, py = np.clip(np.floor(fu), 0, S - 1).astype(int), np.clip(np.floor(fv), 0, S - 1).astype(int)
    dx = np.where(fu - px < border, -1, np.where(fu - px > 1 - border, 1, 0))
    dy = np.where(fv - py < border, -1, np.where(fv - py > 1 - border, 1, 0))
    cand = np.concatenate([np.stack([f, px + ax * dx, py + ay * dy, S], 1) for ax in (0, 1) for ay in (0, 1)])
    cand = cand[(cand[:, 1] >= 0) & (cand[:, 1] < cand[:, 3]) & (cand[:, 2] >= 0) & (cand[:, 2] < cand[:, 3])]
    out = np.unique(cand[:, :3], axis=0)
    return out[np.lexsort((out[:, 1], out[:, 2], out[:, 0]))]


def physical_texel_coords(view, idx):
    """(face, centre u, centre v) of a paged view's physical texels ``idx``: page ``idx // P^2`` (its face and
    place from the view's page_face, page_x, page_y), texel ``idx % P^2`` in it, row by row."""
    page, rest = idx // view.PP_u, idx % view.PP_u
    face = dr.gather(mi.UInt32, view.page_face, page)
    i = dr.gather(mi.UInt32, view.page_x, page) * view.P_u + rest % view.P_u
    j = dr.gather(mi.UInt32, view.page_y, page) * view.P_u + rest // view.P_u
    return face, mi.Float(i) + 0.5, mi.Float(j) + 0.5


def pages_subset(view, pages):
    """A copy of a paged ``view`` holding only ``pages`` (rows of face, page x, page y), its page table rebuilt: the
    pages' texels cast from it are those of the whole view's cast (a texel's ray is its global texel's)."""
    out = copy.copy(view)
    out.pages = np.asarray(pages, int).reshape(-1, 3)
    out.build_page_table()
    return out
