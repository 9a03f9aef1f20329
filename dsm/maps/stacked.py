"""Maps of one view kind built together: one wavefront whose lanes are every map's texels.

A sweep's small maps (one light and view kind at several resolutions) cost a GPU little work
each but a launch and a synchronisation per kernel. Built together, every texel of every map is
one lane of one build: each lane reads its own map's frame, extent and resolution (the view's
opaque scalars, gathered per lane) and its texel index within that map, so a lane computes
exactly what the map's own build computes, the same bits (tests/test_stacked.py holds every
view kind to it). The stacked layers are then cut into one ShadowMap per view on the host (a
copy, no kernel), outside any timed call.

Every build stacks, culled searches too (the per-lane view values are compacted with the
texels still searching, :meth:`View.lanes`), but a cascaded view's (each cascade is its own
fit) and a tiled one's (tiles exist for maps too large to build at once).
"""
from __future__ import annotations

import copy

import drjit as dr
import mitsuba as mi
import numpy as np

from . import shadowmap
from ..scenes import spawn


class _LaneTexels:
    """Mixed into a stacked view's class: texel indices are global over the stack, each lane's
    map resolution and frame are its own (per-lane attributes)."""

    @property
    def n_texels(self) -> int:
        """Texels of every stacked map together."""
        return self.stack_texels

    def texel_coords(self, idx):
        """(face, centre u, centre v) of global texel indices ``idx``, each in its own map."""
        return super().texel_coords(idx - self.lane_first)

    def lanes(self, idx):
        """The stacked view as lanes ``idx`` (a compacted search's texels) see it."""
        out = copy.copy(self)
        for name in self.per_lane:
            value = getattr(self, name)
            setattr(out, name, dr.gather(type(value), value, idx))
        return out


def _per_lane(values, which):
    """The views' values of one opaque attribute (Float, UInt32 or a 3-vector, one each) gathered per lane."""
    t = type(values[0])
    if dr.depth_v(values[0]) == 1:
        table = t(np.concatenate([np.asarray(v.numpy()).ravel() for v in values]))
    else:
        table = t(*(np.array([np.asarray(v[k].numpy()).ravel()[0] for v in values]) for k in range(3)))
    return dr.gather(t, table, which)


def stack_view(views):
    """One view whose lanes are the texels of ``views`` (one kind, face after face, map after map)."""
    cls = type(views[0])
    if any(type(v) is not cls or v.kind != views[0].kind for v in views):
        raise ValueError("stacked maps must share one view kind: "
                         + ", ".join(sorted({v.kind for v in views})))
    if views[0].cascaded:     # each cascade its own fit, held in tables wider than a lane's value
        raise ValueError(f"a {views[0].kind} view with cascades is built alone, not stacked")
    sizes = np.array([v.n_texels for v in views], np.int64)
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    # each lane's map, from the host (4 B a texel): offsets traced as literals would make every
    # stack layout a kernel of its own, compiled again (an OptiX compile on a GPU)
    which = mi.UInt32(np.repeat(np.arange(len(views), dtype=np.uint32), sizes))
    lane = copy.copy(views[0])
    lane.__class__ = type(f"Stacked{cls.__name__}", (_LaneTexels, cls), {})
    lane.per_lane = [name for name, value in vars(views[0]).items()
                     if isinstance(value, dr.ArrayBase) and dr.width(value) == 1]
    for name in lane.per_lane:
        setattr(lane, name, _per_lane([getattr(v, name) for v in views], which))
    # the one Python scalar a build's kernels read: the depth stored where a ray hits nothing
    lane.far = dr.gather(mi.Float, mi.Float(np.array([v.far for v in views], np.float32)), which)
    lane.lane_first = dr.gather(mi.UInt32, mi.UInt32(first.astype(np.uint32)), which)
    lane.per_lane += ["far", "lane_first"]
    lane.stack_texels = int(sizes.sum())
    dr.eval(*(getattr(lane, name) for name in lane.per_lane))
    return lane


def build_arrays(scene, lane, needs, cull_modes=None, extents=None) -> dict:
    """The stacked build of ``lane`` (:func:`stack_view`): layers and per-lane counters by name.
    Timed by the caller; :func:`split` cuts the result into maps."""
    if extents is None and shadowmap.is_layered(needs, cull_modes):
        extents = spawn.shape_extents(scene)
    return shadowmap.build_range(scene, lane, set(needs), cull_modes, 0, lane.stack_texels, extents, lanes=True)[0]


def split(views, layers: dict, culling: str = "none") -> list:
    """One ShadowMap per view from the stacked layers (host copies), each with its own rays,
    re-hits and unfinished texels."""
    host = {k: np.asarray(v.numpy()) for k, v in layers.items()}
    maps, at = [], 0
    for v in views:
        part = {k: a[at:at + v.n_texels] for k, a in host.items()}
        at += v.n_texels
        arrays = {k: (mi.UInt32 if k == "shape" else mi.Float)(a) for k, a in part.items() if not k.startswith("lane_")}
        rays = {"map_texel": v.n_texels, "map_continue": int(part["lane_rays"].sum(dtype=np.int64)) - v.n_texels}
        maps.append(shadowmap.ShadowMap(v, arrays["z1"], arrays["shape"], arrays.get("slope"), z2=arrays.get("z2"),
                                        culling=culling, rays=rays, rehits=int(part["lane_rehit"].sum(dtype=np.int64)),
                                        unfinished=int(part["lane_searching"].sum(dtype=np.int64)), shared=len(views)))
    return maps


def build_together(scene, views, needs, culling: str = "none", cull_modes=None, extents=None) -> list:
    """Build the maps of ``views`` (one kind) in one wavefront: one ShadowMap each, the same bits,
    rays and counts as :func:`dsm.maps.shadowmap.build` of each alone."""
    lane = stack_view(views)
    return split(views, build_arrays(scene, lane, needs, cull_modes, extents), culling)
