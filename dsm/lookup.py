"""Scheme lookup: receivers, taps, parameters as opaque values, filters.

A :class:`Receiver` holds what a scheme may read about the shaded points (position,
geometric normal, depth and map position in the view, texel world size there); a
:class:`Tap` what it may read about one texel (its centre, layers, attributes). Scheme
parameters become opaque Dr.Jit values, so a sweep over values reuses one compiled kernel.

Filters (percentage-closer filtering: the scheme's binary test per tap, then a weighted
mean, so every scheme works with every filter; seed 000, section 5):

- ``nearest``: the texel containing the receiver's map position.
- ``pcf_bilinear``: the four texels whose centres surround the position, weights from the
  fractional position (bilinear interpolation of the four binary results).
- ``pcf_jitter4x4``: 16 taps on a 4 x 4 grid of texel spacing around the position, each
  jittered within its cell by a per-receiver random offset (a fixed seed: runs repeat).

Taps stay on the receiver's face: at a cube edge or the paraboloid rim the index is clamped
to the face rather than continued on the neighbouring face.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi

from .config import Length


@dataclass
class Receiver:
    view: object
    p: object            # mi.Point3f, world
    n: object            # geometric normal (the visible side), world
    to_light: object     # unit vector toward the light
    d: object            # depth in the view's metric
    u: object            # map position, texel units
    v: object
    face: object         # mi.UInt32, the view's face (map) the receiver falls in
    texel_world: object  # world width of one texel at the receiver
    scene_scale: object  # the scene's bounding-box diagonal (opaque scalar)

    @staticmethod
    def make(view, p, n, scene_scale: float) -> "Receiver":
        u, v, face = view.project(p)
        return Receiver(view, p, n, view.to_light(p), view.depth(p), u, v, face, view.texel_world(p),
                        dr.opaque(mi.Float, scene_scale))

    def moved(self, p2) -> "Receiver":
        """The same receiver looked up from another point (normal offset)."""
        u, v, face = self.view.project(p2)
        return dataclasses.replace(self, p=p2, d=self.view.depth(p2), u=u, v=v, face=face)


@dataclass
class Tap:
    view: object
    idx: object          # mi.UInt32 texel index
    face: object
    cu: object           # texel centre, texel units
    cv: object
    z1: object
    shape: object
    slope: object = None
    z2: object = None

    def depth_on_plane(self, p0, n):
        """Depth where the light ray through this texel's centre meets the plane (p0, n)."""
        return self.view.depth_on_plane(self.cu, self.cv, p0, n, self.face)


def tap_at(rx: Receiver, smap, u, v) -> Tap:
    """The texel containing map position (u, v) on the receiver's face (clamped to the face)."""
    view = smap.view
    R1 = mi.Int32(view.R_u) - 1
    i = dr.clip(mi.Int32(dr.floor(u)), 0, R1)
    j = dr.clip(mi.Int32(dr.floor(v)), 0, R1)
    idx = (rx.face * view.R_u + mi.UInt32(j)) * view.R_u + mi.UInt32(i)
    slope = dr.gather(mi.Float, smap.slope, idx) if smap.slope is not None else None
    z2 = dr.gather(mi.Float, smap.z2, idx) if smap.z2 is not None else None
    return Tap(view, idx, rx.face, mi.Float(i) + 0.5, mi.Float(j) + 0.5, dr.gather(mi.Float, smap.z1, idx),
               dr.gather(mi.UInt32, smap.shape, idx), slope, z2)


def nearest_tap(rx: Receiver, smap) -> Tap:
    return tap_at(rx, smap, rx.u, rx.v)


def filter_taps(filt: str, rx: Receiver, seed: int = 7):
    """[(u, v, weight)] of a filter's taps around the receiver's map position."""
    if filt == "nearest":
        return [(rx.u, rx.v, 1.0)]
    if filt == "pcf_bilinear":
        x, y = rx.u - 0.5, rx.v - 0.5
        i0, j0 = dr.floor(x), dr.floor(y)
        fx, fy = x - i0, y - j0
        return [(i0 + 0.5 + a, j0 + 0.5 + b, (fx if a else 1.0 - fx) * (fy if b else 1.0 - fy))
                for a in (0, 1) for b in (0, 1)]
    if filt == "pcf_jitter4x4":
        n = dr.width(rx.u)
        rng = mi.PCG32(n, initstate=dr.arange(mi.UInt64, n), initseq=mi.UInt64(seed))
        taps = []
        for a in range(4):
            for b in range(4):
                taps.append((rx.u + (a - 1.5) + (rng.next_float32() - 0.5),
                             rx.v + (b - 1.5) + (rng.next_float32() - 0.5), 1.0 / 16.0))
        return taps
    raise ValueError(f"unknown filter {filt!r} (valid: nearest, pcf_bilinear, pcf_jitter4x4)")


def resolve(params, rx: Receiver):
    """Scheme parameters as opaque Dr.Jit values in world units (per receiver for texels)."""
    out = {}
    for f in dataclasses.fields(params):
        val = getattr(params, f.name)
        if isinstance(val, Length):
            k = dr.opaque(mi.Float, val.value)
            if val.unit == "texel":
                out[f.name] = k * rx.texel_world
            elif val.unit == "range":
                out[f.name] = k * dr.opaque(mi.Float, rx.view.depth_range)
            else:
                out[f.name] = k
        elif isinstance(val, (int, float)):
            out[f.name] = dr.opaque(mi.Float, float(val))
        else:
            out[f.name] = val
    return SimpleNamespace(**out)


def visibility(scheme, params, rx: Receiver, smap, filt: str = "nearest", seed: int = 7):
    """(V in [0, 1] per receiver, shape index of the nearest texel) for one scheme and filter."""
    prm = resolve(params, rx)
    if hasattr(scheme, "shift"):
        rx = scheme.shift(rx, prm)
    near = nearest_tap(rx, smap)
    if filt == "nearest":
        return dr.select(scheme.lit(rx, near, prm), mi.Float(1.0), mi.Float(0.0)), near.shape
    vis = dr.zeros(mi.Float, dr.width(rx.u))
    for u, v, w in filter_taps(filt, rx, seed):
        vis += dr.select(scheme.lit(rx, tap_at(rx, smap, u, v), prm), w, 0.0)
    return vis, near.shape
