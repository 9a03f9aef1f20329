"""Area lights and their Monte Carlo reference: the visible fraction V* of the light's area.

Shapes (``[[light]] type = "area"``):

- ``rectangle``: centre ``position``, normal ``direction`` (the side it lights; default -z),
  ``size`` = side or ``[width, height]`` along the light frame's axes (:func:`views.light_frame`);
  one-sided.
- ``disk``: centre, normal, ``size`` = diameter; one-sided.
- ``sphere``: centre, ``size`` = diameter. From a receiver it shows the spherical cap facing
  it (points of the sphere seen from there); V* is the fraction of that cap's area visible.
- ``emitter``: the scene's own area emitters (an XML ``<emitter type="area">`` on any mesh,
  the Cornell box's luminaire as it is), one light each, sampled uniformly by area over their
  triangles (a triangle chosen by area with the sample's first coordinate, re-used inside it);
  one-sided, on the side of their winding normal as Mitsuba's area emitter.

V*, the reference: the fraction of the light's area visible from the receiver, by uniform
area samples, unweighted (no cosine, no distance: the quantity shadow-map filters
approximate). A sample below the receiver's tangent plane, or behind a one-sided light, is
not visible. A receiver is a pixel with part of the light above its tangent plane (and in
front of a one-sided light). Each sample is a shadow ray leaving the receiver beyond the
bound on its hit point's error and stopping that far short of the sample
(:func:`dsm.maps.spawn.ray_to`), so the reference holds anywhere in the world.

Sampling (:func:`reference`): randomized quasi-Monte Carlo in ``replicates`` (default 16)
independent replicates, each a jittered stratified set over the light's square parameter domain
(every shape's map from the square to its surface preserves area, so equal cells are equal
areas). Stages: first ``min_samples`` in all, then as many again as taken so far, each replicate
drawing a new jittered set on a finer grid. Random numbers come from the receiver's own
position bits and the experiment's seed, so a receiver's V* does not depend on which other
receivers are in the case.

Interval and stopping rule (:mod:`dsm.truth.intervals`): Student's t over the replicates' means at
``confidence`` (default 0.99), or, where every sample agrees, the zero-count (Clopper-Pearson)
bound, which holds for stratified samples too. A receiver stops once V* is within
``tolerance`` of both ends of its interval, or at ``max_samples``. There is no early stop on
a few agreeing samples: a receiver is umbra or lit only after the zero-count bound is within the
tolerance (459 samples at 99 % and 0.01), so none is called umbra for want of samples.
``capped`` marks receivers left at ``max_samples`` above the tolerance (the run says how many).

Regions: ``umbra`` (no sample visible), ``lit`` (every sample visible), ``penumbra`` (the
rest). The rays are counted per region.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from . import intervals
from ..maps import lookup, spawn
from ..maps.views import ParaboloidView, PerspectiveView, CubeView, light_frame

SHAPES = ("rectangle", "disk", "sphere", "emitter")
PERSPECTIVE_MAX_DEG = 70.0     # beyond this half angle a one-sided light's map is a paraboloid
REGIONS = ("umbra", "penumbra", "lit")
STAGE_LANES = 1 << 23          # shadow rays per launch of a stage: receivers go in chunks (a stage of 2^20
                               # samples over thousands of receivers would pass 2^32 lanes and the memory)


# ---------------------------------------------------------------- geometry

def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def emitter_lights(scene, spec) -> list:
    """One LightSpec per area emitter of ``scene`` (a mesh carrying an area emitter): centre
    (the area-weighted centroid), normal (the area-weighted winding normal), size (the square
    root of its area) and its shape index, which its map excludes. ``spec``: the config's
    ``shape = "emitter"`` light, whose sampling settings they keep."""
    out = []
    for i, shape in enumerate(scene.shapes()):
        if not (shape.is_mesh() and shape.is_emitter()):
            continue
        tri = _triangles(shape)
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        total = float(area.sum())
        if not total > 0:
            continue
        centre = (tri.mean(axis=1) * area[:, None]).sum(0) / total
        normal = _unit(cross.sum(0)) if np.linalg.norm(cross.sum(0)) > 0 else np.array([0.0, 0.0, -1.0])
        out.append(replace(spec, position=tuple(map(float, centre)), direction=tuple(map(float, normal)),
                           size=(math.sqrt(total),), emitter_shapes=(i,), label="area"))
    return out


def _triangles(shape) -> np.ndarray:
    v = np.asarray(shape.vertex_positions_buffer(), np.float64).reshape(-1, 3)
    f = np.asarray(shape.faces_buffer(), np.int64).reshape(-1, 3)
    return v[f]


@dataclass
class Geometry:
    """An area light's surface: the map from the unit square to it (area preserving) and the
    test of which receivers see part of it."""
    shape: str
    centre: np.ndarray
    normal: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    extent: tuple                 # rectangle (w, h); disk, sphere (radius,)
    tris: np.ndarray | None = None    # emitter triangles (n, 3, 3), world, float64
    dist: object = None           # mi.DiscreteDistribution over the triangles' areas
    exclude: tuple = ()

    @property
    def one_sided(self) -> bool:
        """Whether the light lights one side only (every shape but the sphere)."""
        return self.shape != "sphere"

    @property
    def area(self) -> float:
        """The light's surface area in world units squared (an emitter's: its triangles' summed areas)."""
        if self.shape == "rectangle":
            return self.extent[0] * self.extent[1]
        if self.shape == "disk":
            return math.pi * self.extent[0] ** 2
        if self.shape == "sphere":
            return 4 * math.pi * self.extent[0] ** 2
        return float(0.5 * np.linalg.norm(np.cross(self.tris[:, 1] - self.tris[:, 0],
                                                   self.tris[:, 2] - self.tris[:, 0]), axis=1).sum())

    def sample(self, u, v, p):
        """(points, light normals) of square samples (u, v) for receivers at ``p`` (Dr.Jit)."""
        c = mi.Point3f(*map(float, self.centre))
        nrm = mi.Vector3f(*map(float, self.normal))
        ex, ey = mi.Vector3f(*map(float, self.ex)), mi.Vector3f(*map(float, self.ey))
        n = dr.width(u)
        if self.shape == "rectangle":
            w, h = self.extent
            x = c + ex * ((u - 0.5) * w) + ey * ((v - 0.5) * h)
            return x, dr.zeros(mi.Vector3f, n) + nrm
        if self.shape == "disk":
            d = mi.warp.square_to_uniform_disk_concentric(mi.Point2f(u, v)) * self.extent[0]
            return c + ex * d.x + ey * d.y, dr.zeros(mi.Vector3f, n) + nrm
        if self.shape == "sphere":
            r = self.extent[0]
            to_rx = p - c
            dist = dr.norm(to_rx)
            cos_cap = dr.minimum(r / dr.maximum(dist, r), 1.0)
            local = mi.warp.square_to_uniform_cone(mi.Point2f(u, v), cos_cap)
            w = mi.Frame3f(to_rx / dist).to_world(local)
            return c + w * r, w
        idx, u2 = self.dist.sample_reuse(u)
        t = self.tris
        b = mi.warp.square_to_uniform_triangle(mi.Point2f(u2, v))
        corner = [mi.Point3f(*(mi.Float(np.asarray(t[:, k, a], np.float32)) for a in range(3))) for k in range(3)]
        pk = [dr.gather(mi.Point3f, ck, idx) for ck in corner]
        x = pk[0] * (1.0 - b.x - b.y) + pk[1] * b.x + pk[2] * b.y
        return x, dr.normalize(dr.cross(pk[1] - pk[0], pk[2] - pk[0]))

    def receivers(self, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """Whether part of the light is above each receiver's tangent plane (and, for a one-sided
        light, the receiver is in front of it): (m, 3) positions and normals, float64."""
        if self.shape == "rectangle":
            w, h = self.extent
            pts = np.array([self.centre + self.ex * a * w / 2 + self.ey * b * h / 2
                            for a in (-1, 1) for b in (-1, 1)])
            above = ((pts[None] - p[:, None]) * n[:, None]).sum(-1).max(1) > 0
        elif self.shape == "disk":
            r = self.extent[0]
            nn = n - np.outer(n @ self.normal, self.normal)
            above = ((self.centre - p) * n).sum(1) + r * np.linalg.norm(nn, axis=1) > 0
        elif self.shape == "sphere":
            return ((self.centre - p) * n).sum(1) + self.extent[0] > 0
        else:
            verts = self.tris.reshape(-1, 3)
            above = np.zeros(len(p), bool)
            for k in range(0, len(verts), 64):
                above |= ((verts[None, k:k + 64] - p[:, None]) * n[:, None]).sum(-1).max(1) > 0
            # in front of some triangle's emitting side
            tn = np.cross(self.tris[:, 1] - self.tris[:, 0], self.tris[:, 2] - self.tris[:, 0])
            front = np.zeros(len(p), bool)
            for k in range(0, len(tn), 64):
                front |= (((p[:, None] - self.tris[None, k:k + 64, 0]) * tn[None, k:k + 64]).sum(-1) > 0).any(1)
            return above & front
        return above & (((p - self.centre) @ self.normal) > 0)


def geometry(light, scene=None) -> Geometry:
    """The surface of an area LightSpec (``scene``: for emitter lights, their triangles)."""
    c = np.asarray(light.position, float)
    nrm = _unit(light.direction if light.direction is not None else (0.0, 0.0, -1.0))
    ex, ey, _ = light_frame(nrm)
    if light.shape == "rectangle":
        w, h = (light.size * 2)[:2] if len(light.size) == 1 else light.size[:2]
        return Geometry("rectangle", c, nrm, ex, ey, (float(w), float(h)))
    if light.shape in ("disk", "sphere"):
        return Geometry(light.shape, c, nrm, ex, ey, (0.5 * float(light.size[0]),))
    if light.shape == "emitter":
        shapes = list(scene.shapes())
        tris = np.concatenate([_triangles(shapes[i]) for i in light.emitter_shapes])
        area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
        return Geometry("emitter", c, nrm, ex, ey, (), tris, mi.DiscreteDistribution(area.astype(np.float32)),
                        tuple(light.emitter_shapes))
    raise ValueError(f"unknown area light shape {light.shape!r} (valid: {', '.join(SHAPES)})")


def light_size(light) -> float:
    """The light's width in world units (PCSS's light size): the side of a square light, the
    larger side of a rectangle, a disk's or sphere's diameter, an emitter's square root of area."""
    return float(max(light.size)) if light.size else 0.0


# ---------------------------------------------------------------- views

def make_view(light, R, receivers_world, bbox, kind=None):
    """The map of an area light, cast from its centre: for a one-sided light a perspective view
    along its normal whose field of view is fitted to the receivers (``kind`` "fitted"), or a
    paraboloid around the normal when they span more than PERSPECTIVE_MAX_DEG; for a sphere the
    point-light view ``kind``. The view carries ``light_size`` (for PCSS) and ``exclude`` (the
    luminaire's own shapes, which its map steps over)."""
    c = np.asarray(light.position, float)
    nrm = _unit(light.direction if light.direction is not None else (0.0, 0.0, -1.0))
    if light.shape == "sphere":
        if kind == "cube":
            view = CubeView(c, bbox, R)
        elif kind in ("paraboloid", "dual_paraboloid"):
            view = ParaboloidView(c, nrm, bbox, R, dual=kind == "dual_paraboloid")
        else:
            raise ValueError(f"unknown sphere-light view {kind!r} (valid: paraboloid, dual_paraboloid, cube)")
    else:
        pts = np.asarray(receivers_world, float).reshape(-1, 3) - c
        dist = np.linalg.norm(pts, axis=1)
        ok = dist > 0
        cosang = (pts[ok] @ nrm) / dist[ok] if ok.any() else np.ones(1)
        theta = float(np.degrees(np.arccos(np.clip(cosang.min(), -1.0, 1.0))))
        if theta <= PERSPECTIVE_MAX_DEG:
            # the square map's half angle covers the receivers' cone with a little to spare
            view = PerspectiveView(c, nrm, min(max(theta * 1.02 + 0.5, 1.0), PERSPECTIVE_MAX_DEG + 1.0), bbox, R)
        else:
            view = ParaboloidView(c, nrm, bbox, R, dual=False)
    view.light_size = light_size(light)
    view.exclude = tuple(light.emitter_shapes)
    return view


# ---------------------------------------------------------------- reference

def regions(k, n) -> np.ndarray:
    """0 umbra (no sample visible), 1 penumbra, 2 lit (every sample visible)."""
    k, n = np.asarray(k), np.asarray(n)
    return np.where(k == 0, 0, np.where(k == n, 2, 1)).astype(np.uint8)


def _grid(m: int) -> tuple:
    """(a, b) with a * b = m, a the largest divisor of m not above sqrt(m)."""
    a = int(math.isqrt(m))
    while m % a:
        a -= 1
    return m // a, a


def visible(scene, p, n, delta, geom: Geometry, u, v):
    """Whether the light's sample (u, v) is visible from receivers at ``p`` (normals ``n`` on
    the visible side, spawn offsets ``delta``): above the tangent plane, in front of a one-sided
    light, and no surface on the segment (which stops the spawn bound short of the sample)."""
    x, nl = geom.sample(u, v, p)
    d = x - p
    ok = dr.dot(n, d) > 0
    if geom.one_sided:
        ok &= dr.dot(nl, d) < 0
    ray = spawn.ray_to(SimpleNamespace(p=p), n, x, delta)
    return ok & ~scene.ray_test(ray, active=ok)


def sample_visibility(scene, si, n, geom: Geometry, sample, magnitude: float):
    """One random area sample's visibility per surface interaction (an unbiased estimate of
    V*: the plugins' per-sample AOV)."""
    delta = spawn.error_bound(si, dr.opaque(mi.Float, float(magnitude)))
    return visible(scene, si.p, n, delta, geom, sample.x, sample.y)


@dataclass
class Reference:
    """Per receiver: visible samples ``hits`` of ``samples``; V* = hits / samples; ``low`` and
    ``high`` its interval at ``confidence`` (:func:`dsm.truth.intervals.replicate_interval`); ``capped``:
    it reached ``max_samples`` with the interval still wider than the tolerance."""
    hits: np.ndarray
    samples: np.ndarray
    low: np.ndarray
    high: np.ndarray
    capped: np.ndarray
    confidence: float = 0.99

    @property
    def v(self) -> np.ndarray:
        """V* per receiver: hits / samples (0 where no sample was drawn)."""
        return self.hits / np.maximum(self.samples, 1)

    @property
    def half(self) -> np.ndarray:
        """The interval's half-width: the larger distance from V* to its ends."""
        return np.maximum(self.high - self.v, self.v - self.low)

    @property
    def rays(self) -> int:
        """Shadow rays cast over all receivers (the samples summed)."""
        return int(self.samples.sum())

    def take(self, keep: np.ndarray) -> "Reference":
        """The receivers ``keep`` selects (a boolean mask or indices)."""
        return Reference(self.hits[keep], self.samples[keep], self.low[keep], self.high[keep], self.capped[keep],
                         self.confidence)

    def stats(self) -> dict:
        """Receivers, rays and rays per receiver by region; mean and max half-width; receivers
        left at the cap above the tolerance."""
        reg = regions(self.hits, self.samples)
        out = {}
        for i, name in enumerate(REGIONS):
            sel = reg == i
            out[name] = {"receivers": int(sel.sum()), "rays": int(self.samples[sel].sum()),
                         "rays_per_receiver": float(self.samples[sel].mean()) if sel.any() else None}
        out["rays"] = self.rays
        out["confidence"] = self.confidence
        out["capped_above_tolerance"] = int(self.capped.sum())
        half = self.half
        out["half_width_mean"] = float(half.mean()) if half.size else None
        out["half_width_max"] = float(half.max()) if half.size else None
        return out


def empty_reference(confidence: float = 0.99) -> Reference:
    """A reference over no receivers."""
    z = np.zeros(0)
    return Reference(z.astype(np.int64), z.astype(np.int64), z, z, z.astype(bool), confidence)


def _stage_sizes(min_samples: int, max_samples: int, replicates: int) -> list:
    """Samples per replicate added at each stage: ``min_samples`` in all first, then as many as
    taken so far, up to ``max_samples`` (both rounded down to whole replicates, at least one
    sample each)."""
    first = max(min_samples // replicates, 1)
    cap = max(max_samples // replicates, first)
    sizes, total = [first], first
    while total < cap:
        add = min(total, cap - total)
        sizes.append(add)
        total += add
    return sizes


def reference(scene, si, n_rx, geom: Geometry, magnitude: float, seed: int = 7, min_samples: int = 16,
              max_samples: int = 4096, tolerance: float = 0.01, adaptive: bool = True, confidence: float = 0.99,
              replicates: int = 16) -> Reference:
    """The stratified adaptive V* of receivers (surface interactions ``si``, normals ``n_rx``
    facing the camera), in ``replicates`` independent jittered sets: a receiver stops once its
    interval at ``confidence`` is within ``tolerance`` of V* on both sides, or at ``max_samples``.
    ``adaptive=False``: exactly ``max_samples`` per receiver, in the same stages (for
    convergence tests)."""
    count = dr.width(si.p)
    reps = max(1, min(int(replicates), int(min_samples)))
    p_all = mi.Point3f(si.p)
    delta_all = spawn.error_bound(si, dr.opaque(mi.Float, float(magnitude)))
    key_all = lookup.position_key(p_all)
    dr.eval(p_all, delta_all, key_all)
    rep_hits = np.zeros((count, reps), np.int64)
    per_rep = np.zeros(count, np.int64)
    low, high = np.zeros(count), np.ones(count)
    active = np.arange(count, dtype=np.int64)
    sizes = _stage_sizes(min_samples, max_samples, reps)
    for stage, m in enumerate(sizes):
        if not len(active):
            break
        step = max(1, STAGE_LANES // (reps * m))
        for part in (active[i:i + step] for i in range(0, len(active), step)):   # a receiver's rays: its own seeds
            vis = _stage(scene, geom, p_all, n_rx, delta_all, key_all, part, m, reps, seed, stage)
            rep_hits[part] += vis.reshape(len(part), reps, m).sum(2)
        per_rep[active] += m
        _, lo, hi = intervals.replicate_interval(rep_hits[active], int(per_rep[active[0]]), confidence)
        low[active], high[active] = lo, hi
        v = rep_hits[active].sum(1) / (per_rep[active] * reps)
        done = np.maximum(hi - v, v - lo) <= tolerance
        active = active[~done] if adaptive else active
    samples = per_rep * reps
    v = rep_hits.sum(1) / np.maximum(samples, 1)
    capped = np.maximum(high - v, v - low) > tolerance
    return Reference(rep_hits.sum(1), samples, low, high, capped, confidence)


def _stage(scene, geom, p_all, n_rx, delta_all, key_all, active, m, reps, seed, stage) -> np.ndarray:
    """One stage's visibility (len(active) * reps * m, receiver-major, then replicate): each
    replicate a jittered set on an ``a x b`` grid of the light's square, from PCG32 streams keyed
    by the receiver's own position bits and (seed, stage, sample), so a receiver's V* does not
    depend on the others."""
    a, b = _grid(m)
    add = reps * m
    lanes = len(active) * add
    lane = dr.arange(mi.UInt32, lanes)
    r = lane // add
    s = lane % add
    cell = s % m
    ridx = dr.gather(mi.UInt32, mi.UInt32(active.astype(np.uint32)), r)
    p = dr.gather(mi.Point3f, p_all, ridx)
    n = dr.gather(mi.Vector3f, n_rx, ridx)
    delta = dr.gather(mi.Float, delta_all, ridx)
    rng = mi.PCG32()
    rng.seed(mi.UInt64(dr.gather(mi.UInt32, key_all, ridx)),
             mi.UInt64(s) + mi.UInt64((seed & 0xFFFF) * 4096 + stage) * 1048576)
    u = (mi.Float(cell % a) + rng.next_float32()) / a
    v = (mi.Float(cell // a) + rng.next_float32()) / b
    u, v = dr.minimum(u, 0.99999994), dr.minimum(v, 0.99999994)
    return visible(scene, p, n, delta, geom, u, v).numpy().astype(np.int64)
