"""Cascaded shadow maps for directional lights (Microsoft's Common Techniques article; the layouts of Bevy, Godot, TheRealMJP's sample).

A cascaded view is one view of ``N`` faces, one face per cascade, each an orthographic map of
the same light direction with its own square extent and near plane. A receiver is looked up
in the cascade whose range of camera view depth holds its view depth (``face_of``); texel
``(k, i, j)`` is stored at ``k R^2 + j R + i`` as on any view of several faces.

- **Splits** over ``[near, max_distance]`` of the camera (``split_distances``): uniform
  ``n + (f - n) i / N``, log ``n (f / n)^(i / N)``, practical ``lam log + (1 - lam) uniform``;
  engine layouts give their own bounds.
- **Fits** (the light-space square of each cascade): ``receivers`` the receivers' bounds (per
  cascade, those of its range; one cascade: today's single map), ``scene`` the scene's bounding
  box, ``frustum`` the camera's view frustum up to max_distance clipped to the scene's bounds,
  ``cascade`` each cascade's slice of the frustum clipped to the scene's bounds. Every fit
  keeps views.MARGIN_TEXELS texels to spare on each side, as the single map does.
- **Near and far** (``depth_bounds``): ``clipped`` (default) the scene's bounding box clipped to
  the cascade's light prism (Microsoft's Common Techniques article, "Light Frustum Intersected with Scene"), ``scene`` the
  whole box along the light (the naive AABB fit).
- **Stabilization**: each cascade's extent from a bounding sphere of its fitted points, its
  radius rounded up to a fixed quantum (a power of two near 1/256 of the scene's diagonal), and
  its corner at a whole number of texels from a fixed anchor (below and left of the scene's
  bounding box in light space by twice the larger of its diagonal and max_distance, at the
  scene's near plane). A texel ray is computed from the anchor and the
  texel's whole index counted from it, so a texel of the same world place has a bit-identical
  ray in every frame; near and far are the scene's (fixed) bounds.
- **Blend** ``f``: over the last fraction ``f`` of each split (Bevy: of its far bound) the
  receiver's visibility is mixed linearly with the next cascade's.

One depth function for the whole view: the distance along the light from one reference plane
(the lowest near plane), so a texel's depth does not depend on its cascade.
"""
from __future__ import annotations


import dataclasses
import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from . import lookup
from ..core.types import CascadeSpec
from ..scenes.camera import Camera
from .views import MARGIN_TEXELS, View, light_frame

# ---------------------------------------------------------------- splits

def split_distances(kind: str, count: int, near: float, far: float, lam: float = 0.5) -> np.ndarray:
    """The count + 1 split distances from near to far: uniform, log or practical (float64)."""
    if not 0 < near < far:
        raise ValueError(f"cascade splits need 0 < near < far, got near {near:g}, far {far:g}")
    i = np.arange(count + 1) / count
    uniform = near + (far - near) * i
    log = near * (far / near) ** i
    out = {"uniform": uniform, "log": log, "practical": lam * log + (1.0 - lam) * uniform}[kind]
    out[0], out[-1] = near, far
    return out


def layout_splits(spec: CascadeSpec, near: float, max_distance: float, scale: float = 1.0) -> np.ndarray:
    """A layout's split distances: an engine's bounds (world units at scale 1, times ``scale``) or
    fractions of max_distance, else the split kind's."""
    if spec.bounds:
        out = np.array([near] + [b * scale for b in spec.bounds], float)
    elif spec.fractions:
        out = np.array([near] + [f * max_distance for f in spec.fractions], float)
    else:
        return split_distances(spec.split, spec.count, near, max_distance, spec.lam)
    if not np.all(np.diff(out) > 0):
        raise ValueError(f"cascade bounds {out.tolist()} are not increasing (near {near:g})")
    return out


def blend_bands(spec: CascadeSpec, splits: np.ndarray) -> np.ndarray:
    """Width of the blend band at the end of each cascade (0 for the last)."""
    n = len(splits) - 1
    out = np.zeros(n)
    for k in range(n - 1):
        out[k] = spec.blend * (splits[k + 1] if spec.blend_rule == "distance" else splits[k + 1] - splits[k])
    return out


# ---------------------------------------------------------------- convex geometry (float64)

_EDGES = [(i, i | 1 << a) for i in range(8) for a in range(3) if not i >> a & 1]


def _planes(c: np.ndarray):
    """Outward planes (n, d) of a convex hexahedron with corners in bit order (n . p <= d inside)."""
    centre = c.mean(0)
    out = []
    for a in range(3):
        for side in (0, 1):
            p = c[[i for i in range(8) if (i >> a & 1) == side]]
            n = np.cross(p[3] - p[0], p[2] - p[1])
            ln = np.linalg.norm(n)
            if not ln > 0:
                continue
            n = n / ln
            d = float(n @ p.mean(0))
            if n @ centre > d:
                n, d = -n, -d
            out.append((n, d))
    return out


def _inside(pts, planes, tol):
    ok = np.ones(len(pts), bool)
    for n, d in planes:
        ok &= pts @ n <= d + tol
    return ok


def intersect_hexahedra(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The vertices of the intersection of two convex hexahedra (8 corners each, bit order): the
    corners of each inside the other and the crossings of each one's edges with the other's faces.
    Empty (0, 3) when they do not meet."""
    size = max(np.ptp(a, 0).max(), np.ptp(b, 0).max(), 1e-300)
    tol = 1e-9 * size
    pa, pb = _planes(a), _planes(b)
    cand = [a[_inside(a, pb, tol)], b[_inside(b, pa, tol)]]
    for c, planes in ((a, pb), (b, pa)):
        for i, j in _EDGES:
            p, q = c[i], c[j]
            for n, d in planes:
                den = n @ (q - p)
                if den == 0:
                    continue
                t = (d - n @ p) / den
                if 0 <= t <= 1:
                    cand.append((p + t * (q - p))[None])
    pts = np.concatenate(cand)
    return pts[_inside(pts, pa, tol) & _inside(pts, pb, tol)]


def box_corners(lo, hi) -> np.ndarray:
    """The eight corners of the box [lo, hi] as an (8, 3) array (corner i takes hi on axis k when bit k is set)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])


# ---------------------------------------------------------------- the view

def _opaque_vectors(pts):
    pts = np.asarray(pts, float).reshape(-1, 3)
    return mi.Vector3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))


class CascadeView(View):
    """A directional light's cascaded map: one orthographic face per cascade (see the module's notes)."""
    kind = "orthographic"
    cascaded = True

    def __init__(self, direction, spec: CascadeSpec, camera: Camera, receivers_world, scene_bbox, resolution: int,
                 scale: float = 1.0, receivers_f32=None):
        t_start = time.perf_counter()
        ex, ey, ez = light_frame(direction)
        R, N = int(resolution), spec.count
        self.spec, self.camera, self.cascades = spec, camera, N
        self.blend = float(spec.blend) if N > 1 else 0.0
        lo, hi = (np.asarray(b, float) for b in scene_bbox)
        diag = float(np.linalg.norm(hi - lo))

        def to_light(p):        # as views.OrthographicView computes its fit: one dot product per axis
            """World points ``p`` as (n, 3) light-space coordinates along ``ex``, ``ey``, ``ez`` (float64)."""
            p = np.asarray(p, float).reshape(-1, 3)
            return np.stack([p @ ex, p @ ey, p @ ez], axis=1)
        pts = np.asarray(receivers_world, float).reshape(-1, 3)
        # the receivers' view depth, in the float32 arithmetic face_of uses (their cascades exactly)
        t_jit = time.perf_counter()
        rdepth = self._view_depth_f32(camera, pts) if len(pts) else np.zeros(0)
        t_start += time.perf_counter() - t_jit          # fit_ms: the host's float64 work, not this kernel
        near, far = self._split_range(spec, camera, rdepth, scale)
        self.splits = layout_splits(spec, near, far, scale)
        self.bands = blend_bands(spec, self.splits)
        self.cover = [(self.splits[k] - (self.bands[k - 1] if k else 0.0), self.splits[k + 1]) for k in range(N)]
        # the scene's box, padded a hair so a flat scene still has a volume, in light space
        pad = 1e-6 * max(diag, 1e-300)
        box_l = to_light(box_corners(lo - pad, hi + pad))
        zs = box_corners(lo, hi) @ ez
        fit_pts = self._fit_points(pts, rdepth, to_light, box_l, near, far)
        self.stable_quantum = 0.0
        geometry = dict(frame=(ex, ey, ez), box_l=box_l, zs=zs, diag=diag, R=R, m_tex=min(MARGIN_TEXELS, R // 8))
        squares = self._stable_squares(fit_pts, scale, **geometry) if spec.stabilize \
            else self._fitted_squares(fit_pts, **geometry)
        self._place(squares, (ex, ey, ez), R)
        self.fit_ms = (time.perf_counter() - t_start) * 1e3     # splits, fits, near/far (host, float64)

    # ------------------------------------------------------------ the fit, step by step
    def _split_range(self, spec, camera, rdepth, scale) -> tuple:
        """[near, far] of the camera's view depth that the splits divide; sets ``max_distance``."""
        near = camera.near * 1.0 if spec.near is None else spec.near * scale
        if spec.max_distance is not None:
            far = spec.max_distance * scale
            self.max_distance = far
        else:
            far = float(rdepth.max()) if len(rdepth) else camera.far
            self.max_distance = math.inf            # the farthest receiver: none beyond it
        return near, max(far, near * (1 + 1e-6))

    def _fit_points(self, pts, rdepth, to_light, box_l, near, far) -> list:
        """Per cascade, the light-space points its square is fitted to (the ``fit`` choice)."""
        spec, camera, splits, bands = self.spec, self.camera, self.splits, self.bands
        rl = to_light(pts) if len(pts) else np.zeros((0, 3))
        face32 = self._faces(rdepth, splits) if len(pts) else np.zeros(0, int)
        fit_pts = []
        for k in range(self.cascades):
            d0, d1 = self.cover[k]
            if spec.fit == "scene":
                P = box_l
            elif spec.fit == "receivers":
                sel = (face32 == k)
                if k and bands[k - 1] > 0:              # cascade k - 1's blend band reads this one too
                    sel |= (face32 == k - 1) & (rdepth >= splits[k] - bands[k - 1] * (1 + 1e-6))
                P = rl[sel]
                if len(P) == 0:
                    P = self._clipped_slice(camera, d0, d1, to_light, box_l)
            else:
                a, b = (near, far) if spec.fit == "frustum" else (max(d0, near), d1)
                P = self._clipped_slice(camera, a, b, to_light, box_l) if not spec.stabilize \
                    else to_light(camera.frustum(a, b))
            fit_pts.append(P)
        return fit_pts

    def _stable_squares(self, fit_pts, scale, frame, box_l, zs, diag, R, m_tex) -> dict:
        """Stabilized squares: each from a bounding sphere of its points, rounded up to a quantum,
        its corner a whole number of texels from one fixed anchor; near and far the scene's."""
        ex, ey, ez = frame
        q = 2.0 ** (math.floor(math.log2(max(diag, 1e-300))) - 8)
        self.stable_quantum = q
        # the anchor: below and left of every square a cascade can take (the scene's box in light
        # space, less twice the larger of its diagonal and max_distance), so each square's corner is
        # a whole number n >= 0 of texels from it and u = (x s) - n never rounds (0 <= u <= x s)
        reach = 2.0 * max(diag, (self.spec.max_distance or 0.0) * scale)
        ax, ay = box_l[:, 0].min() - reach, box_l[:, 1].min() - reach
        margin = 0.01 * max(zs.max() - zs.min(), diag, 1e-30)
        z0 = zs.min() - margin
        anchor = ex * ax + ey * ay + ez * z0
        out = {k: [] for k in ("rects", "origins", "offsets", "extents", "z0s", "zfar")}
        for P in fit_pts:
            c = P.mean(0)
            r = float(np.linalg.norm(P - c, axis=1).max())
            rq = math.ceil(max(r, q) / q) * q
            extent = 2.0 * rq
            extent *= R / (R - 2 * m_tex)
            texel = extent / R
            nu = math.floor((c[0] - extent / 2 - ax) / texel)
            nv = math.floor((c[1] - extent / 2 - ay) / texel)
            out["origins"].append(anchor)
            out["offsets"].append((float(nu), float(nv)))
            out["extents"].append(extent)
            out["z0s"].append(z0)
            out["zfar"].append(zs.max() + margin)
            out["rects"].append((ax + nu * texel, ay + nv * texel, extent))
        out["ref"] = anchor
        return out

    def _fitted_squares(self, fit_pts, frame, box_l, zs, diag, R, m_tex) -> dict:
        """Squares fitted to each cascade's points with MARGIN_TEXELS texels to spare; near and far
        (``depth_bounds``) the scene's or the scene clipped to the cascade's prism."""
        ex, ey, ez = frame
        out = {k: [] for k in ("rects", "origins", "offsets", "extents", "z0s", "zfar")}
        for P in fit_pts:
            xs, ys = P[:, 0], P[:, 1]
            extent = max(xs.max() - xs.min(), ys.max() - ys.min())
            if not extent > 0:
                extent = max(diag, 1.0) * 1e-3
            extent *= R / (R - 2 * m_tex)
            cx, cy = 0.5 * (xs.max() + xs.min()), 0.5 * (ys.max() + ys.min())
            x0, y0 = cx - extent / 2, cy - extent / 2
            if self.spec.depth_bounds == "scene":
                margin = 0.01 * max(zs.max() - zs.min(), diag, 1e-30)
                z0, zf = zs.min() - margin, zs.max() + margin
            else:
                prism = box_corners((x0, y0, box_l[:, 2].min() - 1.0), (x0 + extent, y0 + extent,
                                                                        box_l[:, 2].max() + 1.0))
                clip = intersect_hexahedra(box_l, prism)
                zl = clip[:, 2] if len(clip) else zs
                margin = 0.01 * max(zl.max() - zl.min(), extent)
                z0, zf = zl.min() - margin, zl.max() + margin
            out["origins"].append(ex * (cx - extent / 2) + ey * (cy - extent / 2) + ez * z0)
            out["offsets"].append((0.0, 0.0))
            out["extents"].append(float(extent))
            out["z0s"].append(z0)
            out["zfar"].append(zf)
            out["rects"].append((x0, y0, extent))
        # one depth function: from the lowest near plane, at the first cascade's corner
        x0, y0, _ = out["rects"][0]
        out["ref"] = out["origins"][0] if self.cascades == 1 else ex * x0 + ey * y0 + ez * min(out["z0s"])
        return out

    def _place(self, sq: dict, frame, R: int):
        """The view's faces from the squares: depth ranges, extents, and the Dr.Jit values the
        lookup reads (opaque, so every fit reuses one kernel)."""
        ex, ey, ez = frame
        N, camera = self.cascades, self.camera
        zref = min(sq["z0s"])
        self.rects = sq["rects"]
        self.face_near = np.array([z - zref for z in sq["z0s"]])
        self.face_far = np.array([f - zref for f in sq["zfar"]])
        self.extents = np.array(sq["extents"])
        View.__init__(self, sq["ref"], ex, ey, ez, R, near=0.0, far=float(self.face_far.max()))
        self.extent = float(self.extents[0])
        off = np.array(sq["offsets"], float)
        self.plain = N == 1 and not self.spec.stabilize       # one cascade: exactly the single orthographic map
        if N == 1:
            self.L = dr.opaque(mi.Float, self.extent)
            self.A = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in sq["origins"][0]))
            self.NU, self.NV = dr.opaque(mi.Float, off[0, 0]), dr.opaque(mi.Float, off[0, 1])
        else:
            self.L = mi.Float(np.float32(self.extents))
            self.A = _opaque_vectors(sq["origins"])
            self.NU = mi.Float(off[:, 0].astype(np.float32))
            self.NV = mi.Float(off[:, 1].astype(np.float32))
        self.cam_o = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.origin))
        self.cam_f = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.forward))
        self.S = [dr.opaque(mi.Float, float(s)) for s in self.splits[1:-1]]
        self.max_o = dr.opaque(mi.Float, float(self.max_distance) if math.isfinite(self.max_distance) else 3e38)

    # ------------------------------------------------------------ helpers
    @staticmethod
    def _view_depth_f32(camera, pts):
        p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
        o = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.origin))
        f = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in camera.forward))
        return np.asarray(dr.dot(p - o, f).numpy(), np.float64)

    @staticmethod
    def _faces(depth, splits):
        s32 = np.asarray(splits, np.float32).astype(np.float64)
        return np.sum(depth[:, None] >= s32[None, 1:-1], axis=1).astype(int)

    @staticmethod
    def _clipped_slice(camera, d0, d1, to_light, box_l):
        sl = to_light(camera.frustum(max(d0, 1e-12), d1))
        clip = intersect_hexahedra(sl, box_l)
        return clip if len(clip) else sl

    @property
    def faces(self) -> int:
        """Faces of the view: one per cascade."""
        return self.cascades

    def _per_face(self, face):
        if self.plain:
            return self.A, self.L, None, None
        if self.cascades == 1:
            return self.A, self.L, self.NU, self.NV
        return (dr.gather(mi.Vector3f, self.A, face), dr.gather(mi.Float, self.L, face),
                dr.gather(mi.Float, self.NU, face), dr.gather(mi.Float, self.NV, face))

    # ------------------------------------------------------------ the View interface
    def view_depth(self, p):
        """The camera's view depth of world points (float32)."""
        return dr.dot(p - self.cam_o, self.cam_f)

    def face_of(self, p):
        """The cascade of world points ``p``: how many split distances their view depth reaches."""
        d = self.view_depth(p)
        face = dr.zeros(mi.UInt32, dr.width(p))
        for s in self.S:
            face += dr.select(d >= s, mi.UInt32(1), mi.UInt32(0))
        return face

    def project_on(self, p, face=None):
        """(u, v) in texels of world points ``p`` on cascade ``face`` (default: each point's own cascade)."""
        face = self.face_of(p) if face is None else face
        A, L, nu, nv = self._per_face(face)
        q = p - A
        x, y = dr.dot(q, self.ex), dr.dot(q, self.ey)
        s = self.R / L
        if nu is None:
            return x * s, y * s
        # stabilized: the position counted from the anchor (the same float32 in every frame), less the
        # whole-texel offset of the square's corner: exact, as 0 <= result <= x s (Sterbenz-like)
        return x * s - nu, y * s - nv

    def ray_at(self, u, v, face=None):
        """(origin, direction) of the light ray through (u, v) of cascade ``face`` (default 0): along ``ez``."""
        face = dr.zeros(mi.UInt32, dr.width(u)) if face is None else face
        A, L, nu, nv = self._per_face(face)
        s = L / self.R
        if nu is None:
            o = A + self.ex * (u * s) + self.ey * (v * s)
        else:
            o = A + self.ex * ((u + nu) * s) + self.ey * ((v + nv) * s)
        return o, dr.zeros(mi.Vector3f, dr.width(o)) + self.ez

    def texel_world(self, p):
        """World width of one texel at points ``p``: their cascade's extent / resolution."""
        _, L, _, _ = self._per_face(self.face_of(p))
        return dr.zeros(mi.Float, dr.width(p)) + L / self.R

    def to_light(self, p):
        """Unit direction from points ``p`` toward the light: ``-ez`` everywhere."""
        return dr.zeros(mi.Vector3f, dr.width(p)) - self.ez

    def inside(self, p):
        """Whether world points ``p`` project within their cascade's square, at a view depth up to ``max_distance``."""
        u, v = self.project_on(p)
        return (u >= 0) & (u <= self.R) & (v >= 0) & (v <= self.R) & (self.view_depth(p) <= self.max_o)

    def texel_bounds(self):
        """Per texel: the near and far of its cascade (the stored formats' range)."""
        n = self.resolution ** 2
        return np.repeat(self.face_near, n), np.repeat(self.face_far, n)

    def signature_arrays(self) -> list:
        """Each cascade's extent, near, far and rectangle, its square's origin and offsets, and the first extent."""
        out = [np.asarray(x, np.float32) for x in (self.extents, self.face_near, self.face_far, self.rects)]
        out += [np.asarray(x.numpy(), np.float32) for x in (self.A, self.NU, self.NV)]
        return out + [np.float32([self.extent])]

    def texel_size(self, k: int) -> float:
        """World width of one texel of cascade k (float64)."""
        return float(self.extents[k]) / self.resolution

    def describe(self) -> list:
        """Per cascade: its range of view depth, texel size, extent, near and far."""
        return [{"cascade": k, "split_near": float(self.splits[k]), "split_far": float(self.splits[k + 1]),
                 "extent": float(self.extents[k]), "texel_size": self.texel_size(k),
                 "near": float(self.face_near[k]), "far": float(self.face_far[k])} for k in range(self.cascades)]


def make_view(light, spec: CascadeSpec, R: int, receivers_world, bbox, sensor, scale: float = 1.0) -> CascadeView:
    """The cascaded view of a directional light for the camera ``sensor`` (a Mitsuba sensor or a Camera)."""
    camera = sensor if isinstance(sensor, Camera) else Camera.from_sensor(sensor)
    return CascadeView(light.direction, spec, camera, receivers_world, bbox, R, scale)


# ---------------------------------------------------------------- blended lookup

def next_cascade(rx):
    """The receivers as the next cascade sees them (the last cascade's stay in it), and the blend
    weight of that next cascade per receiver (0 outside the blend bands)."""
    view = rx.view
    N = view.cascades
    nxt = dr.minimum(rx.face + 1, N - 1)
    u, v = view.project_on(rx.p_world, nxt)
    _, L, _, _ = view._per_face(nxt)
    rx2 = dataclasses.replace(rx, face=nxt, u_map=u, v_map=v, texel_world=dr.zeros(mi.Float, dr.width(u)) + L / view.R)
    d = view.view_depth(rx.p_world)
    ends = mi.Float(np.asarray(view.splits[1:], np.float32))
    bands = mi.Float(np.asarray(view.bands, np.float32))
    end, band = dr.gather(mi.Float, ends, rx.face), dr.gather(mi.Float, bands, rx.face)
    w = dr.select(band > 0, dr.clip((d - (end - band)) / dr.select(band > 0, band, 1.0), 0.0, 1.0), 0.0)
    return rx2, w


def blended_visibility(scheme, params, rx, smap, filt="nearest", seed=7):
    """(V, nearest texel's shape) with the blend band mixing the next cascade's result linearly."""
    v1, shape = lookup.visibility(scheme, params, rx, smap, filt, seed)
    rx2, w = next_cascade(rx)
    v2, _ = lookup.visibility(scheme, params, rx2, smap, filt, seed)
    return v1 * (1.0 - w) + v2 * w, shape


def texels_per_pixel(view: CascadeView, p: np.ndarray, n: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Shadow-map texels per camera pixel at each receiver: the area of its camera pixel's footprint
    on its surface over the area of its texel's (texel_world^2 / |n . light|). Below 1 one texel
    covers several pixels (perspective aliasing, Microsoft's Common Techniques article)."""
    tw = view.extents[face] / view.resolution
    cos_l = np.abs(np.asarray(n, float) @ np.asarray(view.axes_np[2]))
    texel_area = tw ** 2 / np.maximum(cos_l, 1e-12)
    return view.camera.pixel_area(p, n) / texel_area
