"""Shadow maps ray-cast from the light through texel centres.

The first layer ``z1`` (depth of the first hit in the view's metric, the view's far bound
where a texel's ray hits nothing) and the shape of that hit, for attribution, are always
built. Extra attributes are built only when a scheme in the plan needs them:

- ``slope``: the caster's largest depth change per texel step, from the caster's plane at
  the texel (its geometric normal), as rasterizer depth bias computes it.
- ``z2``: the second surface along the texel's ray, found by continuing past the first hit
  from just beyond the bound on its floating-point error (:mod:`dsm.scenes.spawn`); the view's far
  bound where there is none (without culling its depth is taken at ``o + t d`` of the
  continuation ray). A continuation that hits the triangle it left again is counted
  (``rehits``; 0 when the bound holds).

Culling is a property of the build, per shape (``CULL_NONE``, ``CULL_BACK``, ``CULL_FRONT``):
a culled hit is stepped over and the ray goes on. A face is a back face when its winding
normal points along the ray (away from the light).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from ..scenes import spawn
from ..scenes.spawn import COHERENT
from ..core.types import CULLINGS
from ..core.suggest import unknown as unknown_words, valid_words


LAYERS = ("slope", "z2")   # optional attributes a scheme may need (besides z1 and shape)
CULL_NONE, CULL_BACK, CULL_FRONT, CULL_ALL = 0, 1, 2, 3   # CULL_ALL: an area light's luminaire, stepped over
MAX_STEPS = 64             # surfaces stepped over per texel before giving up (reported, never silent)


@dataclass
class ShadowMap:
    """A built map: z1 and the hit's shape per texel, the optional slope and z2 layers, and how the build went."""
    view: object
    z1: object                  # mi.Float, faces*R*R, (face * R + j) * R + i
    shape: object               # mi.UInt32, shape index of the first hit, 0xFFFFFFFF on a miss
    slope: object = None        # mi.Float or None
    z2: object = None           # mi.Float or None
    culling: str = "none"
    unfinished: int = 0         # texels still searching after MAX_STEPS (0 in every sane scene)
    rehits: int = 0             # continuation rays that hit the triangle they left again
    rays: dict = field(default_factory=dict)   # rays cast, by kind
    tiles: int = 1                              # passes the build took (wavefront sizing)
    peak_bytes: int = 0                         # allocation watermark of the build (set by the runner)
    shared: int = 1                             # maps built in one launch with it (dsm.maps.stacked)

    @property
    def resolution(self) -> int:
        """Texels per side of each face (the view's resolution)."""
        return self.view.resolution


def hit_geometry(pi, ray, valid, shape, tables=None):
    """(p, n) of each valid hit: the point interpolated on the triangle and its geometric
    normal. From the meshes' buffers where ``tables`` (:func:`dsm.scenes.spawn.shape_extents`) has
    them (every shape a mesh), else from a minimal surface interaction: the same bits.
    ``shape``: each hit's index into ``scene.shapes()`` (:func:`dsm.scenes.spawn.hit_shape`)."""
    if tables is not None and getattr(tables, "tri_pos", None) is not None:
        return spawn.mesh_hit(pi, shape, tables, valid)
    si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.Minimal, active=valid)
    return si.p, si.n


def first_layer(scene, view, first: int = 0, count: int | None = None, tables=None):
    """(z1, shape index, (hit point, normal, valid), rays) for texels ``first .. first + count - 1``."""
    count = view.n_texels - first if count is None else count
    rays = view.texel_rays(first, count)
    pi = scene.ray_intersect_preliminary(rays, coherent=COHERENT)
    valid = pi.is_valid()
    shape = spawn.hit_shape(pi, valid, tables.by_id if tables is not None else spawn.shape_table(scene))
    # the hit point as every layer and receiver computes it (barycentric on the triangle), then
    # the view's one depth function: a one-layer map and a layered one store the same z1
    p, n = hit_geometry(pi, rays, valid, shape, tables)
    z1 = dr.select(valid, view.depth(p), view.far)
    return z1, shape, (p, n, valid), rays


def plane_slope(view, p, n, z1, valid, first: int = 0):
    """m per texel: |depth change| to the next texel in u and in v on the caster's plane (p, n)."""
    face, cu, cv = view.texel_coords(dr.arange(mi.UInt32, first, first + dr.width(z1)))
    du = dr.abs(view.depth_on_plane(cu + 1.0, cv, p, n, face) - z1)
    dv = dr.abs(view.depth_on_plane(cu, cv + 1.0, p, n, face) - z1)
    return dr.select(valid, dr.maximum(du, dv), 0.0)


def _count(mask) -> int:
    return int(dr.count(mask).numpy().ravel()[0])


ROUND = 2                  # steps of the layered search traced into one kernel (no evaluation between)


def _step(scene, view, st: dict, d, modes, culls: bool, need, want_slope: bool, extents, magnitude) -> dict:
    """One step of every still-searching texel: the preliminary intersection, the hit point and
    geometric normal of a minimal surface interaction, the culling test, the layer it gives and
    the continuation ray. Traced, not evaluated: ROUND steps make one kernel."""
    st = dict(st)
    active, found = st["active"], st["found"]
    ray = mi.Ray3f(st["o"], d)
    st["cast1"] = st["cast1"] + dr.select(active & (found == 0), 1, 0)
    st["cast2"] = st["cast2"] + dr.select(active & (found == 1), 1, 0)
    pi = scene.ray_intersect_preliminary(ray, coherent=COHERENT, active=active)
    valid = active & pi.is_valid()
    shape = spawn.hit_shape(pi, valid, extents.by_id)
    p, n = hit_geometry(pi, ray, valid, shape, extents)
    if culls:
        mode = dr.gather(mi.UInt32, modes, shape, valid & (shape != spawn.NO_SHAPE))
        back = dr.dot(n, d) > 0
        accept = valid & ~(((mode == CULL_BACK) & back) | ((mode == CULL_FRONT) & ~back) | (mode == CULL_ALL))
    else:
        accept = valid
    depth = view.depth(p)
    got1, got2 = accept & (found == 0), accept & (found == 1)
    st["z1"] = dr.select(got1, depth, st["z1"])
    st["shape1"] = dr.select(got1, shape, st["shape1"])
    if want_slope:
        st["p1"] = dr.select(got1, p, st["p1"])
        st["n1"] = dr.select(got1, n, st["n1"])
    st["z2"] = dr.select(got2, depth, st["z2"])
    found = found + dr.select(accept, 1, 0)
    st["found"] = found
    st["rehit"] = st["rehit"] + dr.select(valid & (shape == st["prev_shape"]) & (pi.prim_index == st["prev_prim"])
                                          & _on_mesh(shape, extents), 1, 0)
    st["prev_shape"] = dr.select(valid, shape, st["prev_shape"])
    st["prev_prim"] = dr.select(valid, pi.prim_index, st["prev_prim"])
    active = valid & (found < need)
    st["active"] = active
    delta = spawn.error_bound_by_shape(p, shape, extents, magnitude)
    st["o"] = dr.select(active, spawn.offset_origin(p, n, d, delta), st["o"])
    return st


def _on_mesh(shape, extents):
    """Whether each hit's shape is a triangle mesh. A re-hit (the triangle a continuation ray
    left, hit again) is counted on meshes only: an analytic shape's ``prim_index`` is always 0,
    so its far side would count."""
    known = shape != spawn.NO_SHAPE
    return known & dr.gather(mi.Bool, extents[1], shape, known)


def _first_and_second(scene, view, ray, extents, magnitude):
    """Without culling, per texel: the first hit (z1 from the hit point interpolated on its
    triangle, as :func:`first_layer` stores it) and the second, from one continuation ray that
    leaves the first hit beyond its error bound. The second hit's depth is taken at ``o + t d``
    of that ray: no second vertex fetch; it differs from the interpolated point by rounding,
    far below any bias (z2 is read only by midpoint and dual). Returns (z1, shape1, p1, n1,
    z2, first hit, re-hit of the first triangle), traced, not evaluated."""
    pi = scene.ray_intersect_preliminary(ray, coherent=COHERENT)
    hit1 = pi.is_valid()
    shape1 = spawn.hit_shape(pi, hit1, extents.by_id)
    p1, n1 = hit_geometry(pi, ray, hit1, shape1, extents)
    z1 = dr.select(hit1, view.depth(p1), view.far)
    o2 = spawn.offset_origin(p1, n1, ray.d, spawn.error_bound_by_shape(p1, shape1, extents, magnitude))
    pi2 = scene.ray_intersect_preliminary(mi.Ray3f(o2, ray.d), coherent=COHERENT, active=hit1)
    hit2 = hit1 & pi2.is_valid()
    rehit = hit2 & (spawn.hit_shape(pi2, hit2, extents.by_id) == shape1) & (pi2.prim_index == pi.prim_index) \
        & _on_mesh(shape1, extents)
    z2 = dr.select(hit2, view.depth(dr.fma(ray.d, pi2.t, o2)), view.far)
    return z1, shape1, p1, n1, z2, hit1, rehit


class Layers(NamedTuple):
    """What :func:`layered` builds: the layers, the rays cast by kind and how the search went."""
    z1: object                  # mi.Float per texel
    shape: object               # mi.UInt32, the first accepted hit's shape (NO_SHAPE: none)
    slope: object               # mi.Float or None (not asked)
    z2: object                  # mi.Float or None (not asked)
    rays: dict                  # {"map_texel": n, "map_continue": continuation rays}
    unfinished: int             # texels still searching after MAX_STEPS
    rehits: int                 # continuation rays that hit the triangle they left again
    lanes: dict = None          # per texel (mi.UInt32): "rays" cast, "rehit" re-hits, "searching" (1: unfinished)


def layered(scene, view, cull_modes: np.ndarray, want_z2: bool, want_slope: bool, first: int = 0,
            count: int | None = None, extents=None) -> Layers:
    """First (and second) accepted surface per texel under per-shape culling.

    Without culling, the first hit and one continuation ray make one straight-line kernel
    (:func:`_first_and_second`). With culling the search runs in rounds of ROUND steps, each
    round one kernel (no evaluation or host synchronisation between its steps); after a round
    only the texels still searching go on, compacted (:func:`_search`).
    Per step only what the layer needs: the preliminary intersection, the hit point and
    winding normal from the meshes' buffers (:func:`hit_geometry`), the culling test and the
    continuation ray.
    A step's arithmetic per texel is the same wherever it runs, so the layers are the same bits
    as a search evaluated step by step.

    ``extents``: :func:`dsm.scenes.spawn.shape_extents` of the scene, computed once per scene by the
    caller so that a timed build holds no pass over the meshes (:func:`build` makes them if absent).
    """
    bb = scene.bbox()
    magnitude = dr.opaque(mi.Float, float(np.max(np.abs(np.concatenate([np.ravel(bb.min), np.ravel(bb.max)])))))
    n = view.n_texels - first if count is None else count
    ray = view.texel_rays(first, n)
    culls = bool(np.any(np.asarray(cull_modes) != CULL_NONE))
    if not culls and want_z2:
        # no culling: every texel's search is its first hit and the one continuation ray beyond
        # it, straight-line in one kernel (no working state, no counters updated per step)
        z1, shape1, p1, n1, z2, hit1, rehit = _first_and_second(scene, view, ray, extents, magnitude)
        full = {"z1": z1, "shape1": shape1, "z2": z2, "found": mi.UInt32(hit1)}
        if want_slope:
            full["p1"], full["n1"] = p1, n1
        dr.eval(*full.values(), rehit)
        total, rehits, left = n + _count(full["found"] > 0), _count(rehit), 0
        lanes = {"rays": 1 + full["found"], "rehit": mi.UInt32(rehit), "searching": dr.zeros(mi.UInt32, n)}
    else:
        modes = mi.UInt32(np.asarray(cull_modes, np.uint32))
        full, total, rehits, left = _search(scene, view, ray, modes, culls, 2 if want_z2 else 1, want_slope,
                                            extents, magnitude)
        lanes = {"rays": full["cast1"] + full["cast2"], "rehit": full["rehit"], "searching": mi.UInt32(full["active"])}
    rays = {"map_texel": n, "map_continue": total - n}
    slope = plane_slope(view, full["p1"], full["n1"], full["z1"], full["found"] > 0, first) if want_slope else None
    return Layers(full["z1"], full["shape1"], slope, (full["z2"] if want_z2 else None), rays, left, rehits, lanes)


def _search(scene, view, ray, modes, culls: bool, need: int, want_slope: bool, extents, magnitude) -> tuple:
    """The stepped search of :func:`layered`: (working state per texel, rays cast, re-hits,
    texels still searching), in rounds of ROUND traced steps with the searching texels compacted."""
    n, none = dr.width(ray.d), 0xFFFFFFFF
    # + view.far: a stacked view's far is per lane (dsm.maps.stacked)
    full = {"o": ray.o, "z1": dr.zeros(mi.Float, n) + view.far, "z2": dr.zeros(mi.Float, n) + view.far,
            "shape1": dr.full(mi.UInt32, none, n), "p1": dr.zeros(mi.Point3f, n), "n1": dr.zeros(mi.Vector3f, n),
            "found": dr.zeros(mi.UInt32, n), "active": dr.full(mi.Bool, True, n), "cast1": dr.zeros(mi.UInt32, n),
            "cast2": dr.zeros(mi.UInt32, n), "rehit": dr.zeros(mi.UInt32, n),
            "prev_shape": dr.full(mi.UInt32, none, n), "prev_prim": dr.full(mi.UInt32, none, n)}
    if not want_slope:
        del full["p1"], full["n1"]
    work, where, d = full, None, ray.d        # where: the work set's texels (None: all, in order)
    steps = 0
    while True:
        for _ in range(min(ROUND, MAX_STEPS - steps)):
            work = _step(scene, view, work, d, modes, culls, need, want_slope, extents, magnitude)
        steps += ROUND
        dr.eval(*work.values())
        left = _count(work["active"])          # the one synchronisation per round
        if where is None:
            full = work
        else:
            for k in work:
                dr.scatter(full[k], work[k], where)
        if left == 0 or steps >= MAX_STEPS:
            break
        pick = dr.compress(work["active"])      # the texels still searching, for the next round
        where = pick if where is None else dr.gather(mi.UInt32, where, pick)
        work = {k: dr.gather(type(v), v, pick) for k, v in work.items()}
        d = dr.gather(type(d), d, pick)
        view = view.lanes(pick)                 # a stacked view's per-lane values follow its texels
        dr.eval(*work.values(), d, where)
    dr.eval(*full.values())
    total = int(dr.sum(full["cast1"] + full["cast2"]).numpy().ravel()[0])
    rehits = int(dr.sum(full["rehit"]).numpy().ravel()[0])
    return full, total, rehits, left


def is_layered(needs, cull_modes) -> bool:
    """Whether a build must step along each texel's ray (a second layer or culling)."""
    culls = cull_modes is not None and np.any(np.asarray(cull_modes) != CULL_NONE)
    return bool(culls or "z2" in needs)


def build_range(scene, view, needs, modes, first, count, extents=None, lanes: bool = False):
    """(arrays by name, rays by kind, unfinished texels, re-hits) for one range of texels;
    ``lanes``: the arrays include ``lane_rays``, ``lane_rehit`` and ``lane_searching`` (per texel:
    rays cast, re-hits, 1 where it is still searching), for a caller that splits the range."""
    if not is_layered(needs, modes):
        z1, shape, (p, n, valid), rays = first_layer(scene, view, first, count, extents)
        out = {"z1": z1, "shape": shape}
        if lanes:
            out.update(lane_rays=dr.full(mi.UInt32, 1, count), lane_rehit=dr.zeros(mi.UInt32, count),
                       lane_searching=dr.zeros(mi.UInt32, count))
        if "slope" in needs:
            out["slope"] = plane_slope(view, p, n, z1, valid, first)
        return out, {"map_texel": count, "map_continue": 0}, 0, 0
    modes = modes if modes is not None else np.zeros(len(scene.shapes()), np.uint32)
    lay = layered(scene, view, modes, "z2" in needs, "slope" in needs, first, count, extents)
    out = {"z1": lay.z1, "shape": lay.shape, "slope": lay.slope, "z2": lay.z2}
    if lanes:
        out.update({f"lane_{k}": v for k, v in lay.lanes.items()})
    return {k: v for k, v in out.items() if v is not None}, lay.rays, lay.unfinished, lay.rehits


def build(scene, view, needs, culling: str = "none", cull_modes=None, tile: int | None = None,
          extents=None) -> ShadowMap:
    """Build the layers ``needs`` asks for (a subset of LAYERS) over the whole map.

    ``cull_modes``: one of CULL_* per shape of the scene (index of scene.shapes()); ``culling``
    names the choice for the report. Without culling or a second layer, one ray per texel.
    ``tile``: at most this many texels per pass (a wavefront that fits memory); the passes
    are scattered into one map, identical to a single pass.
    """
    unknown = set(needs) - set(LAYERS)
    if unknown:
        raise ValueError(f"unknown map attributes {sorted(unknown)} ({valid_words(sorted(unknown)[0], LAYERS)})")
    if extents is None and is_layered(needs, cull_modes):
        extents = spawn.shape_extents(scene)        # once for every tile (callers pass them, once per scene)
    n = view.n_texels
    tile = n if not tile or tile >= n else int(tile)
    if tile == n:
        out, rays, unfinished, rehits = build_range(scene, view, needs, cull_modes, 0, n, extents)
        tiles = 1
    else:
        out, rays, unfinished, rehits, tiles = {}, {"map_texel": 0, "map_continue": 0}, 0, 0, 0
        for first in range(0, n, tile):
            count = min(tile, n - first)
            part, r, u, h = build_range(scene, view, needs, cull_modes, first, count, extents)
            idx = dr.arange(mi.UInt32, first, first + count)
            for k, v in part.items():
                if k not in out:
                    out[k] = dr.zeros(type(v), n)
                dr.scatter(out[k], v, idx)
            dr.eval(*out.values())
            for k in rays:
                rays[k] += r[k]
            unfinished += u
            rehits += h
            tiles += 1
    smap = ShadowMap(view, out["z1"], out["shape"], out.get("slope"), rays=rays, z2=out.get("z2"),
                     culling=culling, unfinished=unfinished, rehits=rehits)
    smap.tiles = tiles
    return smap


def cull_modes_for(culling: str, closed: list) -> np.ndarray:
    """Per-shape CULL_* for a culling choice, given each shape's closedness."""
    table = {"none": (CULL_NONE, CULL_NONE), "back": (CULL_BACK, CULL_BACK), "front": (CULL_FRONT, CULL_FRONT),
             "back_closed": (CULL_BACK, CULL_NONE), "front_closed": (CULL_FRONT, CULL_NONE)}
    if culling not in table:
        raise ValueError(unknown_words("culling", culling, table))
    on_closed, on_open = table[culling]
    return np.array([on_closed if c else on_open for c in closed], np.uint32)


def arrays(smap: ShadowMap) -> tuple:
    """The map's Dr.Jit arrays that exist: z1, shape, then slope and z2 when built."""
    return tuple(a for a in (smap.z1, smap.shape, smap.slope, smap.z2) if a is not None)
