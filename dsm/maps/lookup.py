"""Scheme lookup: receivers, taps, parameters as opaque values, filters.

A :class:`Receiver` holds what a scheme may read about the shaded points (position,
geometric normal, depth and map position in the view, texel world size there); a
:class:`Tap` what it may read about one texel (its centre, layers, attributes). Scheme
parameters become opaque Dr.Jit values, so a sweep over values reuses one compiled kernel.

Filters (percentage-closer filtering: the scheme's binary test per tap, then a weighted
mean, so every scheme works with every filter; Weiskopf & Ertl 2003, section 5):

- ``nearest``: the texel containing the receiver's map position.
- ``pcf_bilinear``: the four texels whose centres surround the position, weights from the
  fractional position (bilinear interpolation of the four binary results).
- ``pcf_jitter4x4``: 16 taps on a 4 x 4 grid of texel spacing around the position, each
  jittered within its cell by a per-receiver random offset, seeded from the receiver's own
  position and the experiment's seed (runs repeat; a receiver's taps do not depend on which
  other receivers are in the case).
- ``pcf_wide`` (``pcf_wide:K``): a fixed K x K box kernel of texel spacing centred on the
  position (K = PCF_WIDE_DEFAULT without ``:K``), as engines ship soft shadows of fixed width.
- ``pcss``: percentage-closer soft shadows (Fernando 2005), see :func:`pcss_estimate`: a
  blocker search, the mean blocker depth, the penumbra width by similar triangles, then PCF of
  that width (PCSS_FILTER x PCSS_FILTER taps). Without an area light (``view.light_size``
  absent or 0) the width is one texel.

Taps stay on the receiver's face: at a cube edge or the paraboloid rim the index is clamped
to the face rather than continued on the neighbouring face. Beyond a directional light's
(orthographic) map, which has a margin of a few texels around the receivers, a tap finds no
caster: it reads the far bound, as a texel whose ray hit nothing; so does a texel of a virtual
map's page that no receiver tagged (dsm.maps.virtual: nothing was cast there).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi

from ..core.types import Length
from ..scenes import spawn
from .receiver import Receiver
from ..core.suggest import unknown


def lit(scheme, rx, tap, params):
    """The scheme's binary test: its margin is >= 0."""
    return scheme.margin(rx, tap, params) >= 0


@dataclass
class Tap:
    """What a scheme may read about one texel."""
    view: object
    idx: object          # mi.UInt32 texel index
    face: object
    cu_map: object       # texel centre, texel units
    cv_map: object
    z1: object
    shape: object
    slope: object = None
    z2: object = None

    def depth_on_plane(self, p0, n):
        """Depth where the light ray through this texel's centre meets the plane (p0, n)."""
        return self.view.depth_on_plane(self.cu_map, self.cv_map, p0, n, self.face)

    def receiver_plane_depth(self, rx):
        """The receiver's tangent plane's depth at this texel's centre (receiver_plane, adaptive).

        Where the texel's ray does not meet that plane in front of the light (the plane is
        parallel to the ray, or crosses it behind the light), the receiver's own depth is used:
        the test falls back to the plain depth comparison. :func:`plane_fallbacks` counts those
        receivers for the report."""
        depth, met = self.view.plane_hit(self.cu_map, self.cv_map, rx.p_world, rx.n_world, self.face)
        return dr.select(met, depth, rx.depth)


def tap_at(rx: Receiver, smap, u, v) -> Tap:
    """The texel containing map position (u, v) on the receiver's face (clamped to the face)."""
    view = smap.view
    R1 = mi.Int32(view.face_resolution(rx.face)) - 1
    i = dr.clip(mi.Int32(dr.floor(u)), 0, R1)
    j = dr.clip(mi.Int32(dr.floor(v)), 0, R1)
    idx, absent = view.texel_index(rx.face, i, j)
    slope = dr.gather(mi.Float, smap.slope, idx) if smap.slope is not None else None
    z2 = dr.gather(mi.Float, smap.z2, idx) if smap.z2 is not None else None
    z1 = dr.gather(mi.Float, smap.z1, idx)
    shape = dr.gather(mi.UInt32, smap.shape, idx)
    out = None
    if view.kind == "orthographic":
        # beyond a directional light's map no caster was recorded: the far bound, as a miss
        out = (u < 0) | (v < 0) | (u >= view.R) | (v >= view.R)
    if absent is not None:      # a virtual map's page no receiver tagged: nothing was cast there
        out = absent if out is None else out | absent
    if out is not None:
        z1 = dr.select(out, view.far_o, z1)
        shape = dr.select(out, 0xFFFFFFFF, shape)
        z2 = dr.select(out, view.far_o, z2) if z2 is not None else None
        slope = dr.select(out, 0.0, slope) if slope is not None else None
    return Tap(view, idx, rx.face, mi.Float(i) + 0.5, mi.Float(j) + 0.5, z1, shape, slope, z2)


def nearest_tap(rx: Receiver, smap) -> Tap:
    """The tap of the texel containing each receiver's map position (the nearest lookup)."""
    return tap_at(rx, smap, rx.u_map, rx.v_map)


def position_key(p):
    """An integer per point from its float bits (a hash of x, y, z): the same point, the same key."""
    bits = [dr.reinterpret_array(mi.UInt32, c) for c in (p.x, p.y, p.z)]
    h = bits[0] * 0x9E3779B1
    h = (h ^ (h >> 15)) + bits[1] * 0x85EBCA77
    h = (h ^ (h >> 13)) + bits[2] * 0xC2B2AE3D
    return h ^ (h >> 16)


def position_rng(p, seed: int):
    """A PCG32 per point seeded by its position key and ``seed``: a point's random numbers do not change
    when the points around it change (seed() keeps each lane's state; the constructor would add the lane
    index to the stream)."""
    rng = mi.PCG32()
    rng.seed(mi.UInt64(position_key(p)), dr.full(mi.UInt64, seed, dr.width(p)))
    return rng


def bilinear_taps(u, v):
    """[(u, v, weight)] of the four texel centres around map positions (u, v) (texels), the weights
    bilinear in the fractional position: pcf_bilinear's taps, and dsm grad's bilinear fetch."""
    x, y = u - 0.5, v - 0.5
    i0, j0 = dr.floor(x), dr.floor(y)
    fx, fy = x - i0, y - j0
    return [(i0 + 0.5 + a, j0 + 0.5 + b, (fx if a else 1.0 - fx) * (fy if b else 1.0 - fy))
            for a in (0, 1) for b in (0, 1)]


def filter_taps(filt: str, rx: Receiver, seed: int = 7):
    """[(u, v, weight)] of a filter's taps around the receiver's map position."""
    if filt == "nearest":
        return [(rx.u_map, rx.v_map, 1.0)]
    if filt == "pcf_bilinear":
        return bilinear_taps(rx.u_map, rx.v_map)
    if filt == "pcf_wide" or filt.startswith("pcf_wide:"):
        k = int(filt.split(":", 1)[1]) if ":" in filt else PCF_WIDE_DEFAULT
        w = 1.0 / (k * k)
        return [(rx.u_map + (a - 0.5 * (k - 1)), rx.v_map + (b - 0.5 * (k - 1)), w)
                for a in range(k) for b in range(k)]
    if filt == "pcf_jitter4x4":
        rng = position_rng(rx.p_world, seed)
        taps = []
        for a in range(4):
            for b in range(4):
                taps.append((rx.u_map + (a - 1.5) + (rng.next_float32() - 0.5),
                             rx.v_map + (b - 1.5) + (rng.next_float32() - 0.5), 1.0 / 16.0))
        return taps
    raise ValueError(unknown("filter", filt, ("nearest", "pcf_bilinear", "pcf_jitter4x4", "pcf_wide[:K]", "pcss")))


PCF_WIDE_DEFAULT = 5       # pcf_wide without :K
PCSS_SEARCH = 6            # blocker-search taps per side
PCSS_FILTER = 7            # PCF taps per side over the penumbra width
PCSS_MAX_TEXELS = 64.0     # widest search and filter region, in texels
PCSS_NEAR = 0.125          # the search region's near depth, at least this fraction of the receiver's


def _grid(n: int):
    """Offsets of the cell centres of an n x n grid one unit wide, centred on 0."""
    return [(a + 0.5) / n - 0.5 for a in range(n)]


def pcss_estimate(scheme, prm, rx: Receiver, smap):
    """PCSS's blocker search and penumbra estimate (Fernando 2005), in the kit's units.

    The light (width ``L`` = ``view.light_size``, world) seen from a receiver at depth ``d``
    covers, at depth ``z``, a region ``L (d - z) / d`` wide around the receiver's ray; the map's
    texel there is ``texel_world * z / d`` wide (a map cast from the light's centre), so the
    region spans ``L (d - z) / (z texel_world)`` texels. The search takes it at the near depth
    ``z_n = max(view.nearest_scene_depth, PCSS_NEAR d)`` (Fernando's near plane), capped at
    PCSS_MAX_TEXELS, on a PCSS_SEARCH x PCSS_SEARCH grid. A tap is a blocker where the scheme's
    margin is negative (the scheme's test, per tap). With ``z_b`` the blockers' mean depth the
    penumbra is ``w = L (d - z_b) / z_b`` wide (world, similar triangles), ``w / texel_world``
    texels. Returns (z_b, penumbra width in texels, any blocker found)."""
    view = smap.view
    L = dr.opaque(mi.Float, float(view.light_size))
    d = rx.depth
    z_n = dr.maximum(dr.opaque(mi.Float, float(view.nearest_scene_depth)), PCSS_NEAR * d)
    search = dr.clip(L * (d - z_n) / (z_n * rx.texel_world), 1.0, PCSS_MAX_TEXELS)
    total = dr.zeros(mi.Float, dr.width(d))
    count = dr.zeros(mi.Float, dr.width(d))
    offs = _grid(PCSS_SEARCH)
    for a in offs:
        for b in offs:
            tap = tap_at(rx, smap, rx.u_map + a * search, rx.v_map + b * search)
            blocker = ~lit(scheme, rx, tap, prm)
            total += dr.select(blocker, tap.z1, 0.0)
            count += dr.select(blocker, 1.0, 0.0)
    found = count > 0
    z_b = dr.select(found, total / dr.maximum(count, 1.0), d)
    width = L * (d - z_b) / dr.maximum(z_b, 1e-30) / rx.texel_world
    return z_b, dr.select(found, width, 0.0), found


def pcss(scheme, prm, rx: Receiver, smap):
    """V of the pcss filter: 1 without blockers, else PCF over the estimated penumbra width
    (at least one texel, at most PCSS_MAX_TEXELS)."""
    _, width, found = pcss_estimate(scheme, prm, rx, smap)
    w = dr.clip(width, 1.0, PCSS_MAX_TEXELS)
    vis = dr.zeros(mi.Float, dr.width(rx.u_map))
    offs = _grid(PCSS_FILTER)
    for a in offs:
        for b in offs:
            tap = tap_at(rx, smap, rx.u_map + a * w, rx.v_map + b * w)
            vis += dr.select(lit(scheme, rx, tap, prm), 1.0 / PCSS_FILTER ** 2, 0.0)
    return dr.select(found, vis, 1.0)


def pcss_found(scheme, params, rx: Receiver, smap):
    """Per receiver (lazy Bool), whether PCSS's blocker search finds a blocker (its filter runs only there)."""
    prm = resolve(params, rx)
    return pcss_estimate(scheme, prm, scheme.shift(rx, prm), smap)[2]


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


def plane_misses(scheme, params, rx: Receiver, smap):
    """Per receiver (lazy Bool), whether its nearest texel's ray misses its tangent plane (schemes
    that compare the receiver's plane depth: ``USES_PLANE``); None for other schemes."""
    if not scheme.USES_PLANE:
        return None
    rx = scheme.shift(rx, resolve(params, rx))
    tap = nearest_tap(rx, smap)
    _, met = rx.view.plane_hit(tap.cu_map, tap.cv_map, rx.p_world, rx.n_world, tap.face)
    return ~met


def plane_fallbacks(scheme, params, rx: Receiver, smap) -> int:
    """How many receivers :func:`plane_misses` names (0 for a scheme without a plane)."""
    miss = plane_misses(scheme, params, rx, smap)
    return 0 if miss is None else int(dr.count(miss).numpy().ravel()[0])


SURFACE_SLACK_TEXELS = 0.125   # float32 rounding allowance of the own-surface test, texels at the receiver


def on_own_surface(rx: Receiver, shifted: Receiver, tap: Tap, built):
    """Per receiver (lazy Bool): whether ``tap``'s texel's first hit lies on the receiver's own
    surface, the rule of metrics.csv's ``n_acne_self`` (docs/design.md, *The acne split*).

    ``z_c``: the depth of the receiver's tangent plane (``rx.p_world``, ``rx.n_world``) on the
    texel's centre ray. The texel's depth extent, centre to corner, is taken twice: the receiver
    plane's, half its depth changes to the next texel centres in u and in v, and the hit surface's,
    half the map's own depth changes to the neighbouring texels (per axis the smaller of the two
    sides, so that an outline beside the texel does not count). The hit is on the receiver's
    surface when ``|z1 - z_c| <= min(receiver's, hit's) + s``, ``s = SURFACE_SLACK_TEXELS *
    rx.texel_world`` for float32 rounding where either faces the light (extent 0), taken in the
    view's depth (``depth_per_world``: a VSV grid's depth is an angle's fraction). Every term is a
    length along the light's ray in units of the receiver's own texel: the rule does not depend on
    the scene's scale or position. A hit on the receiver's own triangle lies on that plane and
    passes; a wall standing on the receiver, which faces the light more than the receiver does,
    does not (a contact is an outline). Where the centre ray misses the plane in front of the light
    (grazing light) no hit of it lies on the plane: another surface; where only a neighbour's ray
    misses it, the receiver's extent is unbounded and the hit's decides. A texel whose ray hit
    nothing never holds the receiver's surface. Depths are read from ``built``, the float32 map the stored one was made of (a stored
    format's quantization says nothing about where the hit is); ``shifted``: the receiver as the
    lookup moved it (its face names the texels' map)."""
    view = built.view
    z1 = dr.gather(mi.Float, built.z1, tap.idx)
    z_c = view.depth_on_plane(tap.cu_map, tap.cv_map, rx.p_world, rx.n_world, tap.face)   # +inf: missed
    plane = 0.0
    hit = 0.0
    for du, dv in ((1.0, 0.0), (0.0, 1.0)):
        g = view.depth_on_plane(tap.cu_map + du, tap.cv_map + dv, rx.p_world, rx.n_world, tap.face) - z_c
        plane = plane + 0.5 * dr.abs(g)
        ahead = dr.gather(mi.Float, built.z1, tap_at(shifted, built, tap.cu_map + du, tap.cv_map + dv).idx)
        behind = dr.gather(mi.Float, built.z1, tap_at(shifted, built, tap.cu_map - du, tap.cv_map - dv).idx)
        hit = hit + 0.5 * dr.minimum(dr.abs(ahead - z1), dr.abs(behind - z1))
    plane = dr.select(dr.isfinite(plane), plane, dr.inf)      # a neighbour's ray misses the plane
    slack = SURFACE_SLACK_TEXELS * rx.texel_world * view.depth_per_world(rx.p_world)    # in the view's depth
    near = dr.abs(z1 - z_c) <= dr.minimum(plane, hit) + slack
    return (tap.shape != spawn.NO_SHAPE) & near


def nearest_on_own_surface(scheme, params, rx: Receiver, smap, built):
    """Per receiver (lazy Bool): :func:`on_own_surface` of the nearest texel the scheme's lookup
    reads on ``smap`` (after its shift; ``scheme`` None: no shift, a pre-filtered instance's)."""
    shifted = rx if scheme is None else scheme.shift(rx, resolve(params, rx))
    return on_own_surface(rx, shifted, nearest_tap(shifted, smap), built)


def visibility(scheme, params, rx: Receiver, smap, filt: str = "nearest", seed: int = 7):
    """(V in [0, 1] per receiver, shape index of the nearest texel) for one scheme and filter."""
    prm = resolve(params, rx)
    rx = scheme.shift(rx, prm)
    near = nearest_tap(rx, smap)
    if filt == "nearest":
        return dr.select(lit(scheme, rx, near, prm), mi.Float(1.0), mi.Float(0.0)), near.shape
    if filt == "pcss":
        return pcss(scheme, prm, rx, smap), near.shape
    vis = dr.zeros(mi.Float, dr.width(rx.u_map))
    for u, v, w in filter_taps(filt, rx, seed):
        vis += dr.select(lit(scheme, rx, tap_at(rx, smap, u, v), prm), w, 0.0)
    return vis, near.shape
