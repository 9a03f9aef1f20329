"""Moving casters of a ``[[motion]]`` path: each named shape translated per frame in the Mitsuba scene.

A caster's translation at frame t is linear (``offset`` times t / (frames - 1)) or interpolated
linearly between ``keys`` spread evenly over the frames; like a light's ``light_offset`` it is
multiplied by the scene's ``scale``. Its turn at frame t is ``angle`` times t / (frames - 1)
degrees about ``axis`` through the centre of the shape's loaded bounding box, applied before the
translation. Mitsuba 3 holds a mesh's vertices in ``vertex_positions``
(``mi.traverse``) and rebuilds the scene's acceleration structure on ``params.update()``; the
vertices are moved from their loaded positions in float64 and rounded once per frame, so a frame's
geometry does not depend on the frames before it. The exact side's scene (a scene far from the
origin, :mod:`dsm.scenes.exact_frame`) moves with it. ``restore`` puts every vertex back.
"""
from __future__ import annotations

import numpy as np

import drjit as dr
import mitsuba as mi

from ..core.types import ConfigError


def rotation(axis, deg: float) -> np.ndarray:
    """The 3 x 3 rotation by ``deg`` degrees about ``axis`` (Rodrigues' formula, float64)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = np.radians(deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * (k @ k)


def turns(casters, frames: int) -> np.ndarray:
    """(frames, casters): each caster's turn per frame, degrees."""
    f = np.arange(frames) / (frames - 1)
    return np.stack([f * c.angle for c in casters], axis=1) if casters else np.zeros((frames, 0))


def translations(casters, frames: int, scale: float) -> np.ndarray:
    """(frames, casters, 3): each caster's translation per frame, world units (float64)."""
    out = np.zeros((frames, len(casters), 3))
    for j, c in enumerate(casters):
        for t in range(frames):
            f = t / (frames - 1)
            if c.keys:
                keys = np.asarray(c.keys, float)
                x = f * (len(keys) - 1)
                k = min(int(x), len(keys) - 2)
                out[t, j] = keys[k] * (1 - (x - k)) + keys[k + 1] * (x - k)
            else:
                out[t, j] = np.asarray(c.offset, float) * f
    return out * scale


class Mover:
    """The moving shapes of one path over one scene: their loaded vertices, and each frame's placement."""

    def __init__(self, data, casters, frames: int, source: str, where: str):
        """Check the shapes' names (a ConfigError naming ``source`` and ``where``) and keep their loaded vertices."""
        self.data = data
        self.index = []
        for j, c in enumerate(casters):
            if c.shape not in data.shape_names:
                raise ConfigError(source, f"{where}.casters[{j}].shape",
                                  f"{c.shape!r} is no shape of scene {data.label!r}", tuple(data.shape_names))
            self.index.append(data.shape_names.index(c.shape))
        self.offsets = translations(casters, frames, data.scale)
        self.angles = turns(casters, frames)
        self.axes = [np.asarray(c.axis, float) for c in casters]
        self.flagged = [c.flagged_static for c in casters]
        scenes = [data.scene] + ([data.exact_scene] if data.exact_scene is not None else [])
        self.params = [mi.traverse(s) for s in scenes]
        keys = [f"{data.scene.shapes()[i].id()}.vertex_positions" for i in self.index]
        self.keys = keys
        self.base = [[np.asarray(p[k], np.float64).reshape(-1, 3) for k in keys] for p in self.params]
        self.centres = [0.5 * (v.min(0) + v.max(0)) for v in self.base[0]]   # world: the turns' pivots
        self.placed = None

    @property
    def moving(self) -> bool:
        """Whether any caster moves over the path."""
        return bool(self.index) and bool(np.any(self.offsets != 0.0) or np.any(self.angles % 360.0 != 0.0))

    def shapes(self) -> frozenset:
        """The moving shapes' indices (order of scene.shapes())."""
        return frozenset(self.index)

    def key(self, t: int) -> tuple:
        """What frame ``t``'s geometry is: the casters' translations (equal keys, equal scenes)."""
        return tuple(self.offsets[t].ravel().tolist()) + tuple(self.angles[t].tolist())

    def signature(self, t: int) -> tuple:
        """What the scene's geometry is at frame ``t`` whichever path moves it: the moved shapes, their
        axes and frame ``t``'s translations and turns (equal signatures, equal vertex bits)."""
        return (tuple(self.index), tuple(tuple(a.tolist()) for a in self.axes)) + self.key(t)

    def place(self, t: int) -> bool:
        """Move the casters to frame ``t``'s turns and translations; True if the geometry changed."""
        key = self.key(t)
        if key == self.placed or (self.placed is None and not any(key)):
            self.placed = key
            return False
        exact_shift = np.zeros(3) if self.data.centre is None else np.asarray(self.data.centre, float)
        for s, (params, base) in enumerate(zip(self.params, self.base)):
            for j, (k, v) in enumerate(zip(self.keys, base)):
                pivot = self.centres[j] - (exact_shift if s else 0.0)      # the exact side's scene is centred
                r = rotation(self.axes[j], self.angles[t, j])
                params[k] = mi.Float(((v - pivot) @ r.T + pivot + self.offsets[t, j]).astype(np.float32).ravel())
            params.update()
        dr.eval()
        self.placed = key
        return True

    def restore(self):
        """Every caster back at its loaded place."""
        if self.placed is not None and any(self.placed):
            for params, base in zip(self.params, self.base):
                for k, v in zip(self.keys, base):
                    params[k] = mi.Float(v.astype(np.float32).ravel())
                params.update()
        self.placed = None

    @property
    def any_flagged(self) -> bool:
        """Whether a caster is flagged static (``invalidate`` never re-casts for it)."""
        return any(self.flagged)

    def bounds(self, t: int, invalidating: bool = False) -> list:
        """Each caster's world bounds (lo, hi) at frame ``t`` (``invalidating``: of the casters not
        flagged static): its loaded box's corners turned and moved, which hold the turned shape."""
        out = []
        for j, v in enumerate(self.base[0]):
            if invalidating and self.flagged[j]:
                continue
            b = np.array([v.min(0), v.max(0)])
            corners = np.array([[b[i >> k & 1, k] for k in range(3)] for i in range(8)]) - self.centres[j]
            p = corners @ rotation(self.axes[j], self.angles[t, j]).T + self.centres[j] + self.offsets[t, j]
            out.append((p.min(0), p.max(0)))
        return out

    def swept_bbox(self) -> tuple:
        """The scene's bounds over every frame: the loaded bounds and each caster's at each frame."""
        lo, hi = np.array(self.data.bbox[0], float), np.array(self.data.bbox[1], float)
        for t in range(len(self.offsets)):
            for b_lo, b_hi in self.bounds(t):
                lo, hi = np.minimum(lo, b_lo), np.maximum(hi, b_hi)
        return lo, hi


# a frame's spawn tables hold every triangle of the scene (TRI_STRIDE floats each): kept for the
# next path or map up to this many bytes, so a long path over a large mesh recomputes them instead
KEPT_TABLES_BYTES = 256 << 20


class KeptTables:
    """A scene's per-shape spawn tables (``compute(scene)``) per moved geometry (:meth:`Mover.signature`):
    computed once for every path and map that moves the same casters alike, the same bits (they are a
    function of the vertices), kept while their triangle tables fit ``budget`` bytes."""

    def __init__(self, compute, budget: int = KEPT_TABLES_BYTES):
        self.compute, self.budget, self.used = compute, budget, 0
        self.kept = {}

    def at(self, signature: tuple, scene):
        """The tables of ``scene`` as it stands, whose moved geometry is ``signature``."""
        if signature in self.kept:
            return self.kept[signature]
        tables = self.compute(scene)
        size = 4 * dr.width(tables.tri_pos) if tables.tri_pos is not None else 0
        if self.used + size <= self.budget:
            self.kept[signature] = tables
            self.used += size
        return tables
