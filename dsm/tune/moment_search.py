"""Tuning one pre-filtered instance (dsm.tune.moments): the start, a coarse grid, Adam on the relaxed
loss, the best exact evaluation; then every instance of ``[map] kind`` with its comparisons."""
from __future__ import annotations

import math
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi

from ..report.tables import objective
from ..types import describe_params
from .evaluate import NAN, sync_clock
from .moments import (LR, TAU, gradient_check, grid_search, hard_counts, loss_and_gradient, moment_maps, tunable,
                      with_values)
from .search import BETA1, BETA2, coarse_grid, phase_budgets


def _label(spec) -> str:
    """The instance as steps.csv and table.md name it: kind, filter, parameters."""
    return f"{spec.name} {spec.filter}"


def _row(spec, phase, step, values, hard, **extra) -> dict:
    return {"scheme": _label(spec), "phase": phase, "step": step, "temperature_texel": NAN, "loss": NAN,
            "hard_objective": hard, "time_ms": NAN, **{f"param_{k}": v for k, v in values.items()}, **extra}


def _adam(spec, box, u0: dict, cases, mmaps, steps: int, lam: float, evaluate, rows, start_step: int):
    """``steps`` Adam steps in the unit box from ``u0`` (loss_and_gradient's derivatives), each
    followed by an exact evaluation (``evaluate``)."""
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
        values = {p.name: p.value(u[p.name]) for p in box}
        rows.append({**_row(spec, "gradient", start_step + k, values, evaluate(values)),
                     "temperature_texel": tau, "loss": loss, "time_ms": times[-1]})
    return times


def tune_instance(spec, cases, mmaps, budget: int, lam: float, tick=None) -> dict:
    """Within ``budget`` exact evaluations: the start, a coarse grid (a quarter), Adam from the better
    of the two; the best evaluation is the result."""
    box = tunable(spec)
    rows, best = [], [math.inf, None]

    def evaluate(values: dict) -> float:
        """The exact training objective at ``values``, kept if it is the best so far."""
        obj = objective(hard_counts(with_values(spec, values), cases, mmaps), lam)
        if obj < best[0]:
            best[:] = [obj, dict(values)]
        if tick:
            tick()
        return obj

    share = phase_budgets(budget)
    t0 = sync_clock()
    start = {p.name: p.start for p in box}
    rows.append(_row(spec, "start", 0, start, evaluate(start)))
    cells = coarse_grid([_unit_box(p) for p in box], share["coarse"])
    for i, u in enumerate(cells):
        values = {p.name: p.value(u[p.name]) for p in box}
        rows.append(_row(spec, "coarse", 1 + i, values, evaluate(values)))
    u0 = {p.name: p.unit(best[1][p.name]) for p in box}
    n_adam = budget - 1 - len(cells)
    times = _adam(spec, box, u0, cases, mmaps, n_adam, lam, evaluate, rows, 1 + len(cells))
    return {"values": best[1], "box": box, "steps": rows, "total_ms": (sync_clock() - t0) * 1e3,
            "step_ms": sorted(times)[len(times) // 2] if times else NAN}


def _unit_box(p):
    return SimpleNamespace(name=p.name, lo=0.0, hi=1.0)


def tune_all(tc, train, held, groups, orc_train=None, tick=None) -> tuple:
    """Every pre-filtered instance of the config with lookup-time parameters, tuned, grid-searched and
    gradient-checked (``orc_train``: the depth map's oracle row of the training views, shown beside
    them): (result entries, step rows, notes)."""
    ts, fmt = tc.spec, tc.config.map.format[0]
    entries, steps, notes = [], [], []
    for spec in tc.config.map.moments:
        if not tunable(spec):
            notes.append(f"{_label(spec)}: no lookup-time parameter (its exponent shapes the stored moments: "
                         "sweep it with dsm run)")
            continue
        mm_train, mm_held = moment_maps(spec, train, groups, fmt), moment_maps(spec, held, groups, fmt)
        r = tune_instance(spec, train, mm_train, ts.steps, ts.lam, tick)
        tuned = with_values(spec, r["values"])
        g = grid_search(spec, r["box"], train, mm_train, ts.steps, ts.lam)
        entry = _entry(spec, tuned, r, g, train, held, mm_train, mm_held, ts.lam)
        if orc_train:                       # the depth map's exact floors on the same views, for reference
            entry["depth_oracle_train"] = {k: orc_train[f"{k}_objective"] for k in ("world", "per_texel")}
        entries.append(entry)
        steps += r["steps"]
    return entries, steps, notes


def _entry(spec, tuned, r, g, train, held, mm_train, mm_held, lam) -> dict:
    """One instance's result: values, box, exact objectives of start, tuned and grid on both view sets."""
    obj = lambda s, cases, mm: objective(hard_counts(s, cases, mm), lam) if cases else NAN
    grid_spec = with_values(spec, g["values"])
    return {"kind": spec.name, "filter": spec.filter, "label": _label(spec), "start": describe_params(spec.params),
            "params": describe_params(tuned.params), "values": r["values"],
            "box": {p.name: [p.space, p.lo, p.hi] for p in r["box"]},
            "train": obj(tuned, train, mm_train), "heldout": obj(tuned, held, mm_held),
            "start_train": obj(spec, train, mm_train), "start_heldout": obj(spec, held, mm_held),
            "grid": {"params": describe_params(grid_spec.params), "values": g["values"], "train": g["objective"],
                     "heldout": obj(grid_spec, held, mm_held), "evaluations": g["evaluations"],
                     "total_ms": g["total_ms"]},
            "tune_ms": r["total_ms"], "step_ms": r["step_ms"],
            "gradcheck": gradient_check(spec, r["box"], train, mm_train, lam)}
