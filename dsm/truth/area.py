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
(:func:`dsm.scenes.spawn.ray_to`), so the reference holds anywhere in the world.

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
from dataclasses import dataclass
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from . import intervals
from ..maps import lookup
from ..scenes import spawn
from ..lights.area_surface import Geometry

REGIONS = ("umbra", "penumbra", "lit")
STAGE_LANES = 1 << 23          # shadow rays per launch of a stage: receivers go in chunks (a stage of 2^20
                               # samples over thousands of receivers would pass 2^32 lanes and the memory)


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


def irradiance_fraction(scene, si, n, geom: Geometry, per_axis: int, seed: int, magnitude: float) -> np.ndarray:
    """The irradiance-weighted visible fraction of the light at receivers ``si`` (normals ``n``), float64:
    what a renderer's image over the same image without occluders measures (dsm grad's truth under an
    area light), where V* above is the unweighted fraction a filter approximates. A sample x weighs
    cos(receiver) cos(light) / |x - p|^2 over the area measure (0 below the tangent plane or behind a
    one-sided light); one sample in each cell of a ``per_axis`` x ``per_axis`` grid of the light's
    square, its random numbers keyed by the receiver's position bits and ``seed``, so a receiver reads
    the same samples whatever moves in the scene (common random numbers for a central difference)."""
    count = dr.width(si.p)
    p = mi.Point3f(si.p)
    delta = spawn.error_bound(si, dr.opaque(mi.Float, float(magnitude)))
    rng = mi.PCG32(count, mi.UInt64(lookup.position_key(p)), mi.UInt64(seed))
    seen, total = np.zeros(count), np.zeros(count)
    scale = dr.opaque(mi.Float, 1.0 / per_axis)
    for cell in range(per_axis * per_axis):
        # opaque: the cell's offsets as literals would make every cell a kernel of its own to compile
        i, j = dr.opaque(mi.Float, cell % per_axis), dr.opaque(mi.Float, cell // per_axis)
        u = dr.minimum((i + rng.next_float32()) * scale, 0.99999994)
        v = dr.minimum((j + rng.next_float32()) * scale, 0.99999994)
        dr.eval(u, v, rng.state)          # else the generator's state is a chain that grows with every cell
        x, nl = geom.sample(u, v, p)
        d = x - p
        cosines = dr.maximum(dr.dot(n, d), 0.0) * dr.maximum(-dr.dot(nl, d), 0.0)
        ok = visible(scene, p, n, delta, geom, u, v)
        w = cosines.numpy().astype(np.float64) / dr.squared_norm(d).numpy().astype(np.float64) ** 2
        seen += np.where(ok.numpy(), w, 0.0)
        total += w
    with np.errstate(invalid="ignore", divide="ignore"):       # no part of the light above: undefined
        return np.where(total > 0, seen / np.where(total > 0, total, 1.0), np.nan)


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
