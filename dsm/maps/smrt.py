"""Shadow-map ray tracing (SMRT): soft shadows by rays toward the light, marched through the map.

The ``smrt`` filter (``[map] filter = "smrt:<preset>"`` or ``"smrt:RxS[:rule]"``) estimates the
visible fraction of an area light, as UE5's virtual shadow maps and Blender's EEVEE do with their
shadow-map ray tracing. For each receiver ``p`` (after the scheme's shift) and each of R points
``l_k`` on the light:

- the points: a rank-1 (Fibonacci) lattice over the light's unit square, ``u_k = (k + 1/2) / R``,
  ``v_k = frac(1/2 + k g)`` (``g`` the golden ratio's conjugate), mapped onto the light by its
  area-preserving map (``view.light_surface``, :class:`dsm.lights.area_surface.Geometry`). One ray
  goes to the square's centre, (1/2, 1/2); with R > 1 the lattice is shifted per receiver (toroidally)
  by two numbers drawn from the receiver's own position bits and the seed, as ``pcf_jitter4x4``'s
  jitter, so a run repeats and a receiver's V does not depend on the others (on a scene's emitter
  light the centre of the square is a point of one of its triangles, not its centre). Without a light
  surface (a point, spot or directional light) every ray goes to the map's origin (a directional
  light's: straight along the light), the hard shadow;
- a ray toward a point below the receiver's tangent plane, or behind a one-sided light, is hidden
  (the reference's rule, dsm.truth.area);
- the march: S samples ``x_i = p + t_i (l_k - p)``, ``t_i = ((S - i) / S)^2`` for i = 1..S, from
  the light's end toward the receiver (the last, t = 0, is the receiver itself), spaced as EEVEE's
  tracing loop spaces them (quadratic in the sample index, dense near the receiver). Each sample is
  read on the receiver's own face (its cube face, cascade or virtual level), at the texel containing
  its map position; it is occluded where the scheme's test fails there (its depth behind the stored
  depth by more than the bias), the bias resolved at the receiver;
- a sample behind the stored depth by more than the ray's own depth change since the last sample
  (x 1.05, EEVEE's margin) may have passed behind a surface rather than through it; there, and where
  the map has no data (outside the face, behind its plane, or on a virtual page no receiver tagged),
  ``rule`` decides: ``hold`` (UE5's extrapolation behind occluders, its slope left out: the last
  stored depth the ray saw in front of it, held; a gap without data is held likewise, nothing before
  the first valid sample occludes), ``eevee`` (Blender's shadow tracing library, described and
  re-derived, never copied: a gap is skipped; the last valid occluder depth is extrapolated to the
  sample by its slope between its last two valid samples) or ``plain`` (no extrapolation: each sample
  with data against its own texel);
- V = the fraction of rays no sample of which is occluded.

Cost: R x S taps per lookup (dsm.maps.costs). One ray to the light's centre with a fine march reads,
on an ordinary map, the texel of the receiver's own ray at every sample: V is the nearest lookup's
(tests/test_smrt.py checks it receiver by receiver).
"""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi

from . import lookup
from .receiver import Receiver
from .smrt_presets import PRESETS, RULES, Settings, is_smrt, settings  # noqa: F401 (the filter's API)

GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)     # the Fibonacci lattice's step in v
EEVEE_THRESHOLD = 1.05                    # EEVEE's margin on the ray's depth change ("behind" an occluder)
EVAL_EVERY = 8                            # samples per kernel of the march
EEVEE_MAX_SLOPE = 100.0                   # EEVEE's clamp of the occluder's slope, depth ranges per unit ray time


def lattice(rays: int) -> list:
    """The R points (u, v) of the light's unit square the rays aim at (before a receiver's shift)."""
    return [((k + 0.5) / rays, (0.5 + k * GOLDEN) % 1.0) for k in range(rays)]


def march_times(samples: int) -> list:
    """The S ray times from the light's end to the receiver: ((S - i) / S)^2, i = 1..S (0: the receiver)."""
    return [((samples - i) / samples) ** 2 for i in range(1, samples + 1)]


def ray_targets(rx: Receiver, view, u, v):
    """(light points, visible) per receiver for square samples (u, v): on ``view.light_surface``, with
    rays below the tangent plane or behind a one-sided light hidden; without a surface the map's origin."""
    surface = view.light_surface
    if surface is None:
        if view.kind == "orthographic":      # a directional light: along the light to the map's near side
            return rx.p_world + rx.to_light * view.depth(rx.p_world), dr.full(mi.Bool, True, dr.width(u))
        return dr.zeros(mi.Point3f, dr.width(u)) + view.o, dr.full(mi.Bool, True, dr.width(u))
    x, nl = surface.sample(u, v, rx.p_world)
    d = x - rx.p_world
    ok = dr.dot(rx.n_world, d) > 0
    if surface.one_sided:
        ok &= dr.dot(nl, d) < 0
    return x, ok


def read_sample(rx: Receiver, smap, x):
    """(the sample as a receiver on ``rx``'s face, its tap, whether the map has data there) at world points ``x``."""
    view = smap.view
    u, v = view.project_on(x, rx.face)
    sample = dataclasses.replace(rx, p_world=x, depth=view.depth(x), u_map=u, v_map=v)
    tap = lookup.tap_at(sample, smap, u, v)
    R = mi.Float(view.face_resolution(rx.face))
    valid = (u >= 0) & (v >= 0) & (u < R) & (v < R)
    _, absent = view.texel_index(rx.face, dr.clip(mi.Int32(dr.floor(u)), 0, mi.Int32(R) - 1),
                                 dr.clip(mi.Int32(dr.floor(v)), 0, mi.Int32(R) - 1))
    if absent is not None:
        valid &= ~absent
    if view.kind != "orthographic":
        # a point behind the face's plane (near the light, on another cube face) projects mirrored into it
        o, d = view.ray_at(u, v, rx.face)
        valid &= dr.dot(d, x - o) > 0
    return sample, tap, valid


def occluded(scheme, prm, sample, tap, z_occ):
    """Whether the scheme's test fails for ``sample`` against stored depth ``z_occ`` at ``tap``."""
    return ~lookup.lit(scheme, sample, dataclasses.replace(tap, z1=z_occ), prm)


def trace(scheme, prm, rx: Receiver, smap, target, times, rule: str):
    """Per receiver, whether the ray to ``target`` is occluded, marched at ``times`` by ``rule``
    (module docstring): ``plain`` tests every sample with data against its own texel; ``hold`` and
    ``eevee`` test a sample behind the stored depth (by more than the ray's depth change since the
    last sample, x EEVEE_THRESHOLD) against the last valid occluder depth instead, held (``hold``,
    also over samples without data) or extrapolated by its slope (``eevee``, which skips them)."""
    n = dr.width(rx.depth)
    hit, have = dr.full(mi.Bool, False, n), dr.full(mi.Bool, False, n)
    z_h, recv_h, t_h, slope = (dr.zeros(mi.Float, n) for _ in range(4))
    max_slope = EEVEE_MAX_SLOPE * dr.opaque(mi.Float, float(smap.view.depth_range))
    for i, t in enumerate(times):
        if i % EVAL_EVERY == 0:       # kernels of EVAL_EVERY samples, one compiled for all (a long march's
            dr.eval(hit, have, z_h, recv_h, t_h, slope)     # single kernel took minutes to compile)
        t_o = dr.opaque(mi.Float, t)
        sample, tap, valid = read_sample(rx, smap, rx.p_world + (target - rx.p_world) * t_o)
        if rule == "plain":
            hit |= valid & occluded(scheme, prm, sample, tap, tap.z1)
            continue
        behind = have & valid & (tap.z1 < sample.depth - EEVEE_THRESHOLD * dr.abs(sample.depth - recv_h))
        front = valid & ~behind
        if rule == "hold":
            z = dr.select(front, tap.z1, z_h)
            test = ~hit & (valid | have)
        else:
            z = dr.select(behind, z_h + slope * (t_o - t_h), tap.z1)
            test = ~hit & valid
            dt = t_o - t_h
            grad = dr.clip((tap.z1 - z_h) / dr.select(dt != 0, dt, 1.0), -max_slope, max_slope)
            slope = dr.select(test & front & have, grad, slope)
        hit |= test & occluded(scheme, prm, sample, tap, z)
        keep = test & front
        z_h, t_h = dr.select(keep, tap.z1, z_h), dr.select(keep, t_o, t_h)
        recv_h = dr.select(test & valid, sample.depth, recv_h)
        have |= keep
    return hit


def shifts(rx: Receiver, seed: int):
    """Per receiver, the lattice's toroidal shift (a, b) in [0, 1)^2 from its position bits and ``seed``."""
    rng = lookup.position_rng(rx.p_world, seed + 0x5347)
    return rng.next_float32(), rng.next_float32()


def wrap(x):
    """``x`` modulo 1, kept below 1 in float32 (the light's square is half open)."""
    return dr.minimum(x - dr.floor(x), 0.99999994)


def visibility(scheme, params, rx: Receiver, smap, cfg: Settings, seed: int = 7):
    """(V in [0, 1] per receiver, shape index of the nearest texel): the fraction of ``cfg.rays`` rays
    toward the light no sample of which the scheme's test finds occluded."""
    prm = lookup.resolve(params, rx)
    rx = scheme.shift(rx, prm)
    near = lookup.nearest_tap(rx, smap)
    times = march_times(cfg.samples)
    a, b = shifts(rx, seed) if cfg.rays > 1 else (0.0, 0.0)
    vis = dr.zeros(mi.Float, dr.width(rx.depth))
    for u0, v0 in lattice(cfg.rays):
        u, v = wrap(dr.opaque(mi.Float, u0) + a), wrap(dr.opaque(mi.Float, v0) + b)
        target, ok = ray_targets(rx, smap.view, u, v)
        vis += dr.select(ok & ~trace(scheme, prm, rx, smap, target, times, cfg.rule), 1.0 / cfg.rays, 0.0)
        dr.eval(vis)                             # one kernel per ray: R x S taps need not be one kernel
    return vis, near.shape
