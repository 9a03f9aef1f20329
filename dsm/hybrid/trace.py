"""The hybrid's rays: the receivers a rule picked, traced against the exact scene, and what is left.

:func:`measure` is one hybrid instance on one case: the rule's selection, the rays (timed like a
lookup: Dr.Jit's kernel time between ``dr.sync_thread()`` calls, compilation apart), V after the
rays (a ray's answer where traced, the map's elsewhere) and the error left against V*.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core import timing
from ..truth import metrics
from . import get
from .base import Inputs, Selection
from .origins import rays, shortened

NO_RAYS = timing.Timing(0.0, 0.0, 0.0, 0, 0)


@dataclass(frozen=True)
class Exact:
    """What the rays are traced against: the exact side's scene and light, the receivers' surface
    interactions there (one per receiver, in the case's order) and the scene's magnitude."""
    scene: object
    light: object
    si: object
    magnitude: float


def cast(exact: Exact, idx: np.ndarray, sel: Selection, origin: str, repeats: int) -> tuple:
    """(lit per traced receiver (bool), the rays' Timing) for receivers ``idx``."""
    if idx.size == 0:
        return np.zeros(0, bool), NO_RAYS
    which = mi.UInt32(idx.astype(np.uint32))
    si = dr.gather(mi.SurfaceInteraction3f, exact.si, which)
    span = None
    if sel.t_min is not None:
        span = mi.Float(sel.t_min[idx].astype(np.float32)), mi.Float(sel.t_max[idx].astype(np.float32))
    dr.eval(si, span)

    def run():
        ray = rays(si, exact.light, exact.magnitude, origin)
        if span is not None:
            ray = shortened(ray, *span)
        return (~exact.scene.ray_intersect_preliminary(ray, coherent=False).is_valid(),)
    (lit,), t = timing.measure_kernel(run, repeats)
    return lit.numpy().astype(bool), t


def counts(v: np.ndarray, v_star: np.ndarray) -> dict:
    """Acne, peter-panning and their rates of V against V* (UNDEFINED over an empty denominator)."""
    lit = v >= 0.5
    acne, pp = int(np.count_nonzero(v_star & ~lit)), int(np.count_nonzero(~v_star & lit))
    n, n_lit = int(v.size), int(np.count_nonzero(v_star))
    rate = lambda a, b: a / b if b else metrics.UNDEFINED
    return {"hybrid_n_acne": acne, "hybrid_n_peterpan": pp, "hybrid_acne_rate": rate(acne, n_lit),
            "hybrid_peterpan_rate": rate(pp, n - n_lit), "hybrid_error_rate": rate(acne + pp, n)}


def measure(spec, inputs: Inputs, exact: Exact, repeats: int) -> tuple:
    """(metrics.csv's hybrid columns, V after the rays) of hybrid instance ``spec`` on one case."""
    rule = get(spec.rule)
    sel = rule.select(inputs, spec.params)
    idx = np.flatnonzero(sel.trace)
    lit, t = cast(exact, idx, sel, spec.origin, repeats)
    v = inputs.v_map.astype(np.float64, copy=True)
    v[idx] = lit
    n = inputs.n
    cols = {"hybrid_rule": spec.rule, "hybrid_params": spec.label, "hybrid_origin": spec.origin,
            "hybrid_rays": int(idx.size), "ray_fraction": idx.size / n if n else metrics.UNDEFINED,
            "hybrid_n_ray_wrong": int(np.count_nonzero(lit != inputs.v_star[idx])),
            "hybrid_shortened": int(sel.t_min is not None),
            "hybrid_ms": t.ms, "hybrid_compile_ms": t.compile_ms}
    cols.update(counts(v, inputs.v_star))
    return cols, v
