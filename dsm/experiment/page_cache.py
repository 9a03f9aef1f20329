"""A virtual shadow map's page cache under a ``[[motion]]`` path: the pages cast in earlier frames, kept and
re-cast as the path's cache policy says, and each frame's map composed from them.

A virtual map's pages are re-tagged every frame by that frame's receivers (dsm.maps.virtual). Unreal
Engine 5 keeps the pages it rendered in a physical page pool, re-renders a cached page only when it is
invalidated (a moving primitive's previous and current bounds touch it) and renders the pages a frame needs
that the pool does not hold (Epic's documentation of virtual shadow maps, *Shadow cache invalidation*). Here
a page is named by what its texels' rays are (dsm.maps.views.View.page_keys: its face, place and its level's
rectangle), so a page kept holds exactly what a fresh cast of it would while nothing it sees has moved; a
level that pans with the camera names new pages (UE5 instead keeps its pages across a pan by offsetting its
page table, which the view's one float32 depth origin would not give bit for bit), and a change of the
frame signature (the light's frame, the first level's origin, the levels' widths) empties the pool.

Per page, the policy's rule (dsm.experiment.cache) is asked whether to cast it again, with its own age
and whether a caster moved since it was cast; a partial policy (``invalidate``) casts again the pages whose
texels' rays meet a moving caster's bounds where it was when the page was cast or where it is now (for a page
in use every frame: the last frame's and this one's). A page the pool lacks is cast when first needed, under
every policy. The pool keeps every page ever cast (no eviction)."""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

from . import texel_recast

LAYERS = ("z1", "shape", "slope", "z2")


@dataclasses.dataclass
class Slot:
    """A page in the pool: where its texels lie in the pool's layers, the frame and the casters it was cast with."""
    index: int
    frame: int
    geometry: tuple


@dataclasses.dataclass
class PagePool:
    """The pages cast so far for one frame signature: their slots and their texels' layers (slot-major)."""
    signature: bytes = b""
    slots: dict = dataclasses.field(default_factory=dict)      # page key -> Slot
    layers: dict = dataclasses.field(default_factory=dict)     # layer name -> Dr.Jit array (slots x page texels)

    def reset(self, signature: bytes):
        """Empty the pool for views of frame signature ``signature``."""
        self.signature, self.slots, self.layers = signature, {}, {}


def touched_pages(view, boxes) -> np.ndarray:
    """Per stored page of ``view``, whether the ray of any of its texels meets one of ``boxes`` [(lo, hi)]
    (the texels' test of dsm.experiment.texel_recast, grown by its float32 margin)."""
    if not boxes:
        return np.zeros(len(view.page_keys()), bool)
    return texel_recast.touched(view, boxes).reshape(-1, view.page_size ** 2).any(1)


def plan(pool: PagePool, view, frame: int, geometry: tuple, rule, partial: bool, bounds) -> np.ndarray:
    """Per stored page of ``view``, whether frame ``frame`` casts it: not in the pool, or the policy's ``rule``
    (view_changed, geometry_changed, age) says so, or (``partial``) ``bounds(f)`` of the casters at the frame
    ``f`` it was cast and at this one touch it."""
    keys = view.page_keys()
    cast = np.array([k not in pool.slots for k in keys], bool)
    for i, key in enumerate(keys):
        slot = pool.slots.get(key)
        if slot is not None:
            cast[i] = rule(False, slot.geometry != geometry, frame - slot.frame)
    if partial:
        for f in sorted({s.frame for k in keys if (s := pool.slots.get(k)) is not None and s.geometry != geometry}):
            of = np.array([(s := pool.slots.get(k)) is not None and s.frame == f and s.geometry != geometry
                           for k in keys])
            cast |= of & touched_pages(view, bounds(f) + bounds(frame))
    return cast


def stale(pool: PagePool, view, cast: np.ndarray, geometry: tuple) -> bool:
    """Whether a page the frame keeps was cast with casters placed otherwise than now (its map may differ from a
    fresh one: ghosts and missing shadows are counted against a fresh cast)."""
    return any(pool.slots[k].geometry != geometry for k, c in zip(view.page_keys(), cast) if not c)


def compose(pool: PagePool, view, cast: np.ndarray, part, frame: int, geometry: tuple, base):
    """This frame's map on ``view``: the pages ``cast`` from ``part`` (the map of ``view.with_pages`` of those
    pages, in their order; None where none is cast), the others from the pool; the pool takes the cast pages.
    ``base``: a ShadowMap whose build record the composed map carries (``part``, or the last frame's map)."""
    keys, pp = view.page_keys(), view.page_size ** 2
    old_n = len(pool.slots)
    for i in np.flatnonzero(cast):           # a re-cast page keeps its slot; a new one takes the next
        old = pool.slots.get(keys[i])
        pool.slots[keys[i]] = Slot(old.index if old else len(pool.slots), frame, geometry)
    slot_of = np.array([pool.slots[k].index for k in keys], np.int64)
    part_of = np.full(len(keys), -1, np.int64)
    part_of[cast] = np.arange(int(cast.sum()))
    texel = np.arange(pp, dtype=np.int64)
    # the pool after this frame: per slot, its texels from the part where cast now, else where they were
    from_part = np.full(len(pool.slots), -1, np.int64)
    from_part[slot_of[cast]] = part_of[cast]
    pool_src = (from_part[:, None] * pp + texel).ravel()
    keep_src = (np.arange(len(pool.slots))[:, None] * pp + texel).ravel()
    new_layers = {}
    for name in LAYERS:
        new_layers[name] = _merged(pool.layers.get(name), None if part is None else getattr(part, name),
                                   pool_src, keep_src, old_n * pp)
    pool.layers = new_layers
    idx = mi.UInt32(((slot_of[:, None] * pp) + texel).ravel().astype(np.uint32))
    out = {n: None if a is None else dr.gather(type(a), a, idx) for n, a in new_layers.items()}
    smap = dataclasses.replace(base, view=view, **out)
    dr.eval(*(a for a in out.values() if a is not None))
    return smap


def _merged(old, part, part_src: np.ndarray, keep_src: np.ndarray, old_texels: int):
    """A layer of the pool after a frame: texel k from ``part`` at ``part_src[k]`` where that is >= 0, else
    from ``old`` at ``keep_src[k]`` (a slot new this frame is always from the part)."""
    if old is None and part is None:
        return None
    use_part = part_src >= 0
    if old is None or old_texels == 0:
        return dr.gather(type(part), part, mi.UInt32(part_src.astype(np.uint32)))
    kept = dr.gather(type(old), old, mi.UInt32(np.where(use_part, 0, keep_src).astype(np.uint32)))
    if part is None:
        return kept
    fresh = dr.gather(type(part), part, mi.UInt32(np.where(use_part, part_src, 0).astype(np.uint32)))
    return dr.select(mi.Bool(use_part), fresh, kept)
