"""Tuning one pre-filtered instance (dsm.tune.moments): the start, a coarse grid, Adam on the relaxed
loss, the best exact evaluation; then every instance of ``[map] kind`` with its comparisons."""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi

from ..report.tables import objective
from ..core.types import describe_params
from .evaluate import NAN, sync_clock
from .moments import (LR, TAU, gradient_check, grid_search, hard_counts, loss_and_gradient, map_source, tunable,
                      unit_box, with_values)
from .search import BETA1, BETA2, coarse_grid, phase_budgets


def _label(spec) -> str:
    """The instance as steps.csv and table.md name it: kind, its start (preset or parameters), filter."""
    return " ".join(x for x in (spec.name, spec.preset or spec.label, spec.filter) if x)


def _row(spec, phase, step, values, hard, **extra) -> dict:
    return {"scheme": _label(spec), "phase": phase, "step": step, "temperature_texel": NAN, "loss": NAN,
            "hard_objective": hard, "time_ms": NAN, **{f"param_{k}": v for k, v in values.items()}, **extra}


def _adam(spec, box, u0: dict, cases, mmaps, steps: int, lam: float, evaluate, rows, start_step: int, base=None):
    """``steps`` Adam steps in the unit box from ``u0`` (loss_and_gradient's derivatives), each
    followed by an exact evaluation (``evaluate``); ``base``: the values of the parameters held
    (the moments' own, whose maps ``mmaps`` are), evaluated with them."""
    base = base or {}
    spec = with_values(spec, base) if base else spec
    opt = mi.ad.Adam(lr=LR, beta_1=BETA1, beta_2=BETA2)
    for p in box:
        opt[p.name] = mi.Float(u0[p.name])
    u, times = dict(u0), []
    for k in range(steps):
        tau = TAU[0] * (TAU[1] / TAU[0]) ** (k / max(steps - 1, 1))
        t0 = sync_clock()
        loss, grads = loss_and_gradient(spec, box, u, cases, mmaps, tau, lam)
        for p in box:
            dr.set_grad(opt[p.name], mi.Float(grads[p.name]))
        opt.step()
        for p in box:
            opt[p.name] = dr.clip(dr.detach(opt[p.name]), 0.0, 1.0)
        u = {p.name: float(opt[p.name][0]) for p in box}
        times.append((sync_clock() - t0) * 1e3)
        values = {**base, **{p.name: p.value(u[p.name]) for p in box}}
        rows.append({**_row(spec, "gradient", start_step + k, values, evaluate(values)),
                     "temperature_texel": tau, "loss": loss, "time_ms": times[-1]})
    return times


def tune_instance(spec, box, cases, maps_for, budget: int, lam: float, tick=None) -> dict:
    """Within ``budget`` exact evaluations: the start, a coarse grid (a quarter; half where every
    parameter is the moments' own), then golden-section search of each parameter of the moments (a
    new build per value: no gradient) near the best, then Adam on the lookup's parameters at the best
    moments (the rest); the best evaluation is the result."""
    rows, best = [], [math.inf, None]

    def evaluate(values: dict) -> float:
        """The exact training objective at ``values``, kept if it is the best so far."""
        obj = objective(hard_counts(with_values(spec, values), cases, maps_for(values)), lam)
        if obj < best[0]:
            best[:] = [obj, dict(values)]
        if tick:
            tick()
        return obj

    rebuild = all(p.rebuild for p in box)
    t0 = sync_clock()
    start = {p.name: p.start for p in box}
    rows.append(_row(spec, "start", 0, start, evaluate(start)))
    cells = coarse_grid(unit_box(box), (budget - 1) // 2 if rebuild else phase_budgets(budget)["coarse"])
    for i, u in enumerate(cells):
        values = {p.name: p.value(u[p.name]) for p in box}
        rows.append(_row(spec, "coarse", 1 + i, values, evaluate(values)))
    rest, step = budget - 1 - len(cells), 1 + len(cells)
    width = 1.0 / max(round(len(cells) ** (1.0 / len(box))), 1)        # a coarse cell, in the unit coordinate
    moment_params = [p for p in box if p.rebuild]
    lookup_params = [p for p in box if not p.rebuild]
    times = []
    for i, p in enumerate(moment_params):        # each of the moments' own, the others at the best so far
        n = rest // len(moment_params) if not lookup_params else rest // (2 * len(moment_params))
        times += _golden(spec, p, dict(best[1]), width, n, evaluate, rows, step)
        step, rest = step + n, rest - n
    if lookup_params:                            # then Adam on the lookup's, at the best moments
        held = {p.name: best[1][p.name] for p in moment_params}
        u0 = {p.name: p.unit(best[1][p.name]) for p in lookup_params}
        times += _adam(spec, lookup_params, u0, cases, maps_for(held), rest, lam, evaluate, rows, step, held)
    return {"values": best[1], "box": box, "steps": rows, "total_ms": (sync_clock() - t0) * 1e3,
            "step_ms": sorted(times)[len(times) // 2] if times else NAN}


GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def _golden(spec, p, base: dict, width: float, steps: int, evaluate, rows, start_step: int) -> list:
    """Golden-section search of parameter ``p`` (the others at ``base``, the best so far) within a
    coarse cell ``width`` of its best value (its unit coordinate, clipped to the box) with ``steps``
    evaluations: for a piecewise-constant objective a local search, kept honest by the
    best-evaluation rule."""
    u_best = p.unit(base[p.name])
    lo, hi = max(u_best - width, 0.0), min(u_best + width, 1.0)
    times = []

    def at(u: float) -> float:
        t0 = sync_clock()
        v = {**base, p.name: p.value(u)}
        obj = evaluate(v)
        times.append((sync_clock() - t0) * 1e3)
        rows.append(_row(spec, "line", start_step + len(times) - 1, v, obj))
        return obj
    a, b = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
    fa, fb = (at(a), at(b)) if steps >= 2 else (math.inf, math.inf)
    for _ in range(max(steps - 2, 0)):
        if fa <= fb:
            hi, b, fb = b, a, fa
            a = hi - GOLDEN * (hi - lo)
            fa = at(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + GOLDEN * (hi - lo)
            fb = at(b)
    return times


def tune_all(tc, train, held, groups, orc_train=None, tick=None) -> tuple:
    """Every pre-filtered instance of the config with a tuned parameter, tuned, grid-searched and
    (parameters of the lookup) gradient-checked (``orc_train``: the depth map's oracle row of the
    training views, shown beside them): (result entries, step rows, notes)."""
    ts, fmt = tc.spec, tc.config.map.format[0]
    entries, steps, notes = [], [], []
    for spec in tc.config.map.moments:
        box = tunable(spec, fmt)
        if not box:
            notes.append(f"{_label(spec)}: no parameter of its kind declares a tune box (sweep it with dsm run)")
            continue
        src_train, src_held = map_source(spec, box, train, groups, fmt), map_source(spec, box, held, groups, fmt)
        r = tune_instance(spec, box, train, src_train, ts.steps, ts.lam, tick)
        g = grid_search(spec, box, train, src_train, ts.steps, ts.lam)
        entry = _entry(spec, r, g, train, held, src_train, src_held, ts.lam)
        if orc_train:                       # the depth map's exact floors on the same views, for reference
            entry["depth_oracle_train"] = {k: orc_train[f"{k}_objective"] for k in ("world", "per_texel")}
        entries.append(entry)
        steps += r["steps"]
    return entries, steps, notes


def _entry(spec, r, g, train, held, src_train, src_held, lam) -> dict:
    """One instance's result: values, box, exact objectives of start, tuned and grid on both view sets."""
    def obj(values, cases, src):
        """The exact objective at ``values`` over ``cases`` (NaN without any)."""
        return objective(hard_counts(with_values(spec, values), cases, src(values)), lam) if cases else NAN
    start = {p.name: p.start for p in r["box"]}
    rebuild = any(p.rebuild for p in r["box"])
    lookup = [p for p in r["box"] if not p.rebuild]      # the parameters with a gradient, checked at the start
    return {"kind": spec.name, "filter": spec.filter, "label": _label(spec), "start": describe_params(spec.params),
            "params": describe_params(with_values(spec, r["values"]).params), "values": r["values"],
            "all_values": dataclasses.asdict(with_values(spec, r["values"]).params),
            "box": {p.name: [p.space, p.lo, p.hi] for p in r["box"]}, "rebuilt": rebuild,
            "train": obj(r["values"], train, src_train), "heldout": obj(r["values"], held, src_held),
            "start_train": obj(start, train, src_train), "start_heldout": obj(start, held, src_held),
            "grid": {"params": describe_params(with_values(spec, g["values"]).params), "values": g["values"],
                     "train": g["objective"], "heldout": obj(g["values"], held, src_held),
                     "evaluations": g["evaluations"], "total_ms": g["total_ms"]},
            "tune_ms": r["total_ms"], "step_ms": r["step_ms"],
            "gradcheck": gradient_check(spec, lookup, train, src_train(start), lam) if lookup else {}}
