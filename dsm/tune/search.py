"""Tuning one scheme: its search box, the coarse grid, Adam on the relaxed loss, then exact refinement."""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..report.tables import objective
from ..core.types import Length, SchemeSpec
from .evaluate import NAN, hard_counts, sync_clock, with_values
from .relax import relaxed_loss
from .refine import exact_refinement, line_reach
from ..config.tune import TuneSpec, valid_min


BETA1 = 0.5              # Adam's first-moment decay (0.9 carries the iterate past the flat optimum of a
                         # piecewise-constant objective when the gradient flips as the temperature falls)
BETA2 = 0.9              # and second-moment decay: the gradient's scale falls by orders of magnitude as the
                         # iterate leaves the dense thresholds and the temperature drops; 0.999 remembers the
                         # early scale and stalls the steps


# ---------------------------------------------------------------- tuning one scheme

@dataclass
class Param:
    """One tuned parameter: its unit, start, step scale (one texel's worth in its unit) and search range."""
    name: str
    unit: str                  # world | texel | range | "" (a plain number)
    start: float
    scale: float
    lo: float
    hi: float


# parameters that are lengths without being Lengths: K multiplies the scene's diagonal (adaptive)
DIAGONAL_FRACTIONS = {("adaptive", "K")}
DEPTH_OFFSETS = ("bias", "depth_bias")     # parameters added to the receiver's depth as they are
BOX_TEXELS = 16.0         # the default search range: [valid minimum or 0, start + 16 texels' worth], widened
                          # to twice the thresholds' best values (search_box)


def texel_sizes(train, groups) -> dict:
    """One texel's worth in each unit, over the training receivers: world (the mean texel
    width), range (that over the mean depth range), diagonal (that over the mean scene diagonal)."""
    tw = float(np.mean(np.concatenate([c.th.texel_world for c in train]).astype(np.float64)))
    used = sorted({c.group for c in train})
    rng = float(np.mean([groups[g].view.depth_range for g in used]))
    diag = float(np.mean([groups[g].diagonal for g in used]))
    return {"texel": 1.0, "world": tw, "range": tw / rng, "diagonal": tw / diag, "": 1.0}


def start_value(spec, name: str) -> float:
    """A scheme instance's value of parameter ``name`` in its own unit (a Length's number, or the number)."""
    cur = getattr(spec.params, name)
    return cur.value if isinstance(cur, Length) else float(cur)


def _unit_and_scale(spec, name: str, sizes) -> tuple:
    """Parameter ``name``'s unit ("" for a plain number) and one texel's worth in it (``sizes``: texel_sizes)."""
    cur = getattr(spec.params, name)
    unit = cur.unit if isinstance(cur, Length) else ""
    return unit, sizes["diagonal" if (spec.name, name) in DIAGONAL_FRACTIONS else unit]


def _line_floor(module, name: str):
    """Where a parameter's values start: its valid minimum; None (unbounded) for a depth offset
    without one (affine in the margin, so its line best is exact, and a large lambda, preferring
    acne to peter-panning, can put it below 0); else 0."""
    vmin = valid_min(module, name)
    if vmin is not None:
        return vmin
    return None if name in DEPTH_OFFSETS else 0.0


def search_box(tc, spec, sizes, oracle_best=None, line_best=None) -> list:
    """Each tuned parameter: its start, its step scale (one texel's worth in its unit; 1 for
    factors on the slope) and its search range. The default range reaches twice the best value
    the thresholds give, so it holds it: ``oracle_best``, the exact oracle's best constant bias of
    the training views per unit (world, texel); ``line_best``, per parameter the best along its
    line from the start (refine.line_reach)."""
    from ..schemes import get
    mod = get(spec.name)
    out = []
    for name in tc.spec.params[spec.name]:
        v = start_value(spec, name)
        unit, scale = _unit_and_scale(spec, name, sizes)
        vmin = valid_min(mod, name)
        best = (oracle_best or {}).get(unit) if (spec.name, name) == ("constant", "bias") else None
        bests = [b for b in (best, (line_best or {}).get(name)) if b is not None and math.isfinite(b)]
        reach = 2.0 * max(bests) if bests else 0.0
        floor = _line_floor(mod, name)           # None: below 0 to twice a negative best
        low = floor if floor is not None else min([0.0] + [2.0 * b for b in bests])
        lo, hi = tc.spec.ranges.get((spec.name, name), (min(low, v), max(max(v, 0.0) + BOX_TEXELS * scale, reach)))
        if vmin is not None:
            lo = max(lo, vmin)
        out.append(Param(name, unit, min(max(v, lo), hi), scale, lo, hi))
    return out


def _line_bests(tc, spec, train, groups, sizes) -> dict:
    """Per tuned parameter without a range of the user's, the best value along its line from the
    start (the others at their starts), from the receivers' flips (refine.line_reach)."""
    from ..schemes import get
    mod = get(spec.name)
    names = tc.spec.params[spec.name]
    start = {n: start_value(spec, n) for n in names}
    return {n: line_reach(mod, spec, start, n, _line_floor(mod, n), _unit_and_scale(spec, n, sizes)[1],
                          train, groups, tc.spec.lam)
            for n in names if (spec.name, n) not in tc.spec.ranges}


def temperature_at(spec: TuneSpec, step: int, steps: int) -> float:
    """The temperature in texels at ``step`` of ``steps``: geometric or linear from its start to its end."""
    t0, t1 = spec.temperature
    f = step / max(steps - 1, 1)
    return t0 * (t1 / t0) ** f if spec.schedule == "geometric" else t0 + (t1 - t0) * f


def _batch_weights(spec: TuneSpec, cases, rng):
    if spec.batch >= 1.0:
        return None
    return [mi.Float((rng.random(c.n) < spec.batch).astype(np.float32) / spec.batch) for c in cases]


COARSE_SHARE = 4          # a quarter of the evaluations (after the start) for the coarse grid


def _evaluation_row(spec, phase, step, values, hard, **extra) -> dict:
    """One row of steps.csv: an evaluation of the exact objective (its phase: start, coarse, gradient)."""
    return {"scheme": spec.name, "phase": phase, "step": step, "temperature_texel": NAN, "loss": NAN,
            "hard_objective": hard, "time_ms": NAN, **{f"param_{k}": v for k, v in values.items()}, **extra}


def coarse_grid(box, budget: int) -> list:
    """At most ``budget`` points of a regular grid over ``box``, at cell centres (k per parameter,
    k = floor(budget^(1/p)))."""
    k = max(1, int(math.floor(budget ** (1.0 / len(box)) + 1e-9))) if budget >= 1 else 0
    if k == 0:
        return []
    axes = [b.lo + (np.arange(k) + 0.5) * (b.hi - b.lo) / k for b in box]
    return [{b.name: float(x) for b, x in zip(box, combo)}
            for combo in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(box))]


def phase_budgets(steps: int) -> dict:
    """How ``steps`` exact evaluations are spent: the start, a coarse grid (a quarter of the rest),
    the exact local refinement (another quarter), Adam steps (what remains)."""
    coarse = refine = (steps - 1) // COARSE_SHARE
    return {"start": 1, "coarse": coarse, "gradient": steps - 1 - coarse - refine, "refine": refine}


def tune_scheme(tc, spec: SchemeSpec, train, groups, progress=None, oracle_best=None) -> dict:
    """Within ``steps`` evaluations of the exact training objective: the start, a coarse grid of
    the search box (a quarter of them), Adam on the relaxed loss from the better of the two
    (one evaluation per step), then a compass search on the exact objective around the best
    point so far (the last quarter). The best evaluation is returned, so the result is never
    worse than the start or any point the search saw. Per evaluation its phase, the loss,
    the exact objective and the step's time."""
    ts = tc.spec
    sizes = texel_sizes(train, groups)
    box = search_box(tc, spec, sizes, oracle_best, _line_bests(tc, spec, train, groups, sizes))
    exact = lambda vals: objective(hard_counts(with_values(spec, vals), train, groups), ts.lam)
    budget = phase_budgets(ts.steps)
    start = {p.name: p.start for p in box}
    best = (exact(start), start)
    rows = [_evaluation_row(spec, "start", 0, start, best[0])]
    grid = coarse_grid(box, budget["coarse"])
    corner, anchor = _anchor_points(box, oracle_best)
    extra = [v for v in (corner, anchor) if v is not None and v != start][:budget["coarse"]]
    grid = grid[:min(len(grid), budget["coarse"] - len(extra))] + extra      # the coarse share holds them all
    origin = best                       # Adam's: the best but the oracle's anchor (a basin of its own)
    for vals in grid:
        rows.append(_evaluation_row(spec, "coarse", len(rows), vals, exact(vals)))
        if rows[-1]["hard_objective"] < best[0]:
            best = (rows[-1]["hard_objective"], vals)
        if rows[-1]["hard_objective"] < origin[0] and vals is not anchor:
            origin = (rows[-1]["hard_objective"], vals)
    for _ in rows:
        if progress:
            progress()
    # a coarse grid may hold fewer points than its share (k^p <= share): Adam takes the rest
    # (the anchor's evaluation is taken from the refinement's share: Adam's schedule stays the grid's)
    n_adam = ts.steps - len(rows) - budget["refine"] + (anchor is not None and anchor in grid)
    adam = _adam(tc, spec, box, train, groups, origin[1], n_adam, len(rows), progress)
    for r in adam["rows"]:
        vals = {p.name: r[f"param_{p.name}"] for p in box}
        if r["hard_objective"] < best[0] and all(math.isfinite(v) for v in vals.values()):
            best = (r["hard_objective"], vals)        # a diverged step (NaN) is never a result
    rows += adam["rows"]
    k = max(1, round(len(grid) ** (1.0 / len(box)))) if grid else 1
    ref = exact_refinement(spec, box, best, train, groups, ts.lam, exact, ts.steps - len(rows), k)
    for phase, vals, obj in ref["evaluations"]:
        rows.append(_evaluation_row(spec, phase, len(rows), vals, obj))
        if progress:
            progress()
    best = ref["best"]
    times = [r["time_ms"] for r in adam["rows"]] or [0.0]
    return {"values": best[1], "box": box, "steps": rows, "relaxed_lookup": adam["relax"],
            "first_step_ms": times[0], "step_ms": float(np.median(times[1:])) if len(times) > 1 else times[0],
            "total_ms": float(sum(times)) + ref["ms"], "refine_ms": ref["ms"], "evaluations": len(rows)}


def _anchor_points(box, oracle_best) -> tuple:
    """Two points the coarse grid's cell centres never reach, evaluated in place of its last cells:
    the box's lower corner (every term at its least: a term is often best off) and, for a scheme
    with a depth offset in a unit the exact oracle answers (world, texel), that corner with the
    offset at the oracle's best constant bias (else None), the oracle's own answer wherever the
    other terms at their least add nothing (normal offset 0, slope scale 0). The anchor is a
    candidate for the result and the refinement, not Adam's start: from it Adam stays in the
    constant bias's basin where the grid's best leads elsewhere (lambda = 1000)."""
    corner = {p.name: p.lo for p in box}
    for p in box:
        best = (oracle_best or {}).get(p.unit)
        if p.name in DEPTH_OFFSETS and best is not None and math.isfinite(best):
            return corner, {**corner, p.name: min(max(best, p.lo), p.hi)}
    return corner, None


def _adam(tc, spec, box, train, groups, origin: dict, steps: int, first: int, progress=None) -> dict:
    """``steps`` Adam steps on the relaxed loss from ``origin``; each step's exact objective."""
    from ..schemes import get
    mod, ts = get(spec.name), tc.spec
    rng = np.random.default_rng(ts.seed)
    opt = mi.ad.Adam(lr=ts.lr, beta_1=BETA1, beta_2=BETA2)
    for p in box:
        opt[p.name] = mi.Float(origin[p.name] / p.scale)
    rows, relax = [], False
    for step in range(steps):
        t_texels = temperature_at(ts, step, steps)
        w = _batch_weights(ts, train, rng)
        opt.set_learning_rate(ts.lr * t_texels / ts.temperature[0])      # steps shrink with the temperature
        t0 = sync_clock()
        values = {p.name: opt[p.name] * p.scale for p in box}
        loss, relax = relaxed_loss(mod, spec.params, values, train, groups, t_texels, ts.lam, w)
        dr.backward(loss)
        grads = {p.name: float(dr.grad(opt[p.name]).numpy().ravel()[0]) / p.scale for p in box}
        opt.step()
        for p in box:
            opt[p.name] = dr.clip(opt[p.name], p.lo / p.scale, p.hi / p.scale)
        dr.eval(*[opt[p.name] for p in box])
        ms = (sync_clock() - t0) * 1e3
        cur = {p.name: float(opt[p.name].numpy().ravel()[0]) * p.scale for p in box}
        hard = objective(hard_counts(with_values(spec, cur), train, groups), ts.lam)
        rows.append({**_evaluation_row(spec, "gradient", first + step, cur, hard), "temperature_texel": t_texels,
                     "loss": float(loss.numpy().ravel()[0]), "time_ms": ms,
                     **{f"grad_{k}": g for k, g in grads.items()}})
        if progress:
            progress()
    return {"rows": rows, "relax": relax}
