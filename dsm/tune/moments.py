"""dsm tune of the pre-filtered map kinds (``[map] kind``): each instance's lookup-time parameters
fitted by gradient through its continuous V, judged by the exact objective.

A kind's field whose metadata has ``"tune": (space, lo, hi)`` is a lookup-time parameter (VSM's and
EVSM's minimum variance and bleed reduction, MSM's moment and depth biases): the stored moments do
not depend on it, so one moment map per (scene, light) serves every evaluation. The exponents of ESM
and EVSM (``"tune": (space, lo, hi, "moments")``) shape the stored moments: each value is a new
build, so they are searched exactly (a grid, then golden-section search near the best:
dsm.tune.moment_search), without a gradient; a box stops at the largest exponent the format holds.
Each parameter is searched in a unit coordinate u in [0, 1] over its box, log-spaced (``log``: a
variance or a bias spanning decades) or linear.

**Relaxation.** V is already continuous in these parameters, so the relaxed "lit" is
``s = sigmoid((V - 1/2) / tau)``, tau (in V) annealed geometrically from ``TAU[0]`` to ``TAU[1]``
over the Adam steps; the loss and the exact objective are the schemes' (dsm.tune.tuner). The
search is the schemes' budget split: the start, a coarse grid (a quarter of ``steps``), Adam for the
rest, the best exact evaluation the result (never worse than the start); a grid with as many
evaluations over the same box is the comparison.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline as pl
from .. import prefilter
from ..report.tables import objective
from .evaluate import counted, sync_clock
from .search import coarse_grid

TAU = (0.1, 0.005)        # the sigmoid's width in V, first and last Adam step
LR = 0.05                 # Adam's step in the unit coordinate
GRADCHECK_H = 1e-2        # central difference's half step in the unit coordinate


@dataclass
class MomentParam:
    """One tuned lookup-time parameter: its search space (log or linear), box and start."""
    name: str
    space: str
    lo: float
    hi: float
    start: float
    rebuild: bool = False      # the stored moments depend on it: a new moment map per value

    def unit(self, x: float) -> float:
        """The value ``x`` as the unit coordinate in [0, 1] of the box."""
        if self.space == "log":
            x = max(x, self.lo)
            return min(max(math.log(x / self.lo) / math.log(self.hi / self.lo), 0.0), 1.0)
        return min(max((x - self.lo) / (self.hi - self.lo), 0.0), 1.0)

    def value(self, u):
        """The parameter at unit coordinate ``u`` (a float or a Dr.Jit Float, differentiable)."""
        if self.space == "log":
            return self.lo * (dr.exp(u * math.log(self.hi / self.lo)) if not isinstance(u, float)
                              else math.exp(u * math.log(self.hi / self.lo)))
        return self.lo + u * (self.hi - self.lo)


def tunable(spec, fmt: str = "float32") -> list:
    """The tuned parameters of a MomentSpec (fields declaring a ``tune`` box), each at its start; a
    parameter of the moments themselves stops at the largest exponent ``fmt`` holds (LOG_MAX)."""
    out = []
    for f in dataclasses.fields(spec.params):
        box = f.metadata.get("tune")
        if box:
            rebuild = len(box) > 3 and box[3] == "moments"
            hi = _held(spec, f.name, float(box[1]), float(box[2]), fmt) if rebuild else float(box[2])
            out.append(MomentParam(f.name, box[0], float(box[1]), hi, float(getattr(spec.params, f.name)), rebuild))
    return out


def _held(spec, name: str, lo: float, hi: float, fmt: str) -> float:
    """The largest value of parameter ``name`` in [lo, hi] whose moments ``fmt`` holds (the kind's
    log_max, non-decreasing in an exponent, at most LOG_MAX): bisected."""
    log_max = prefilter.get(spec.name).log_max
    limit = prefilter.LOG_MAX.get(fmt, math.inf)

    def fits(v) -> bool:
        top = log_max(dataclasses.replace(spec.params, **{name: v}))
        return top is None or top <= limit

    if fits(hi):
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def map_source(spec, box, cases, groups, fmt: str):
    """A function from parameter values to the moment maps of the cases' groups: one set built once
    where no tuned parameter shapes the moments, else built per value of those (the last kept)."""
    if not any(p.rebuild for p in box):
        fixed = moment_maps(spec, cases, groups, fmt)
        return lambda values: fixed
    last = {}

    def maps_for(values: dict) -> dict:
        """The moment maps of the instance at ``values`` (its moment parameters)."""
        key = tuple(float(values[p.name]) for p in box if p.rebuild)
        if key not in last:
            last.clear()
            last[key] = moment_maps(with_values(spec, values), cases, groups, fmt)
        return last[key]
    return maps_for


def with_values(spec, values: dict):
    """The instance with tuned ``values`` (exact floats)."""
    return dataclasses.replace(spec, params=dataclasses.replace(spec.params, **{k: float(v) for k, v in values.items()}))


def moment_maps(spec, cases, groups, fmt: str) -> dict:
    """The instance's MomentMap per (scene, light) group the cases read, from its float32 depth map."""
    return {g: pl.moment_map(spec, groups[g].maps["none"], fmt) for g in sorted({c.group for c in cases})}


def hard_counts(spec, cases, mmaps) -> dict:
    """Exact counts of one instance over ``cases``: the kit's own pre-filtered lookup (lit: V >= 0.5)."""
    return counted(cases, lambda c: prefilter.visibility(spec, c.rx, mmaps[c.group]))


def loss_and_gradient(spec, box, u: dict, cases, mmaps, tau: float, lam: float) -> tuple:
    """(the relaxed loss, its derivative per parameter in the unit coordinate) at ``u`` (floats):
    (sum over truly lit (1 - s) + lambda sum over truly shadowed s) / n, s = sigmoid((V - 1/2) / tau).
    Forward-mode AD per parameter gives each receiver's dV/du; a receiver whose derivative is not
    finite (an unselected branch of the lookup, such as MSM's quotient where no root lies in front,
    differentiates to 0 * inf) adds 0, as does one whose V is not finite."""
    total, grads, n = 0.0, {p.name: 0.0 for p in box}, 0
    inv_tau = dr.opaque(mi.Float, 1.0 / tau)       # opaque, as the parameters: one kernel for every step
    for c in cases:
        for k, p in enumerate(box):
            uf = {q.name: dr.opaque(mi.Float, u[q.name]) for q in box}
            dr.enable_grad(uf[p.name])
            v = prefilter.visibility(spec, c.rx, mmaps[c.group], {q.name: q.value(uf[q.name]) for q in box})
            dr.forward(uf[p.name])
            dv = dr.grad(v)
            v = dr.detach(v)
            ok = dr.isfinite(v)
            x = dr.select(ok, (v - 0.5) * inv_tau, -30.0)
            inside = ok & (dr.abs(x) < 30.0)
            s = 1.0 / (1.0 + dr.exp(-dr.clip(x, -30.0, 30.0)))
            ds = dr.select(inside & dr.isfinite(dv), s * (1.0 - s) * inv_tau * dv, 0.0)
            grads[p.name] += float(dr.sum(dr.select(c.v_star_dr, -ds, lam * ds))[0])
            if k == 0:
                total += float(dr.sum(dr.select(c.v_star_dr, 1.0 - s, lam * s))[0])
        n += c.n
    n = max(n, 1)
    return total / n, {k: g / n for k, g in grads.items()}


def relaxed_loss_np(spec, box, u: dict, cases, mmaps, tau: float, lam: float) -> float:
    """The same relaxed loss from the kit's forward V in numpy float64 (the gradient check's second computation)."""
    inst = with_values(spec, {p.name: p.value(float(u[p.name])) for p in box})
    total, n = 0.0, 0
    for c in cases:
        v = np.asarray(prefilter.visibility(inst, c.rx, mmaps[c.group]).numpy(), np.float64)
        x = np.where(np.isfinite(v), (v - 0.5) / tau, -30.0)
        s = 1.0 / (1.0 + np.exp(-np.clip(x, -30.0, 30.0)))
        total += float(np.where(c.v_star, 1.0 - s, lam * s).sum())
        n += c.n
    return total / max(n, 1)


def gradient_check(spec, box, cases, mmaps, lam: float) -> dict:
    """Per parameter at the start and the first tau: loss_and_gradient's derivative in u against a
    central difference (half step GRADCHECK_H) of relaxed_loss_np."""
    at = {q.name: q.unit(q.start) for q in box}
    out = {}
    for p in box:
        u0 = min(max(at[p.name], GRADCHECK_H), 1.0 - GRADCHECK_H)
        here = {**at, p.name: u0}
        ad = loss_and_gradient(spec, box, here, cases, mmaps, TAU[0], lam)[1][p.name]
        lo = relaxed_loss_np(spec, box, {**here, p.name: u0 - GRADCHECK_H}, cases, mmaps, TAU[0], lam)
        hi = relaxed_loss_np(spec, box, {**here, p.name: u0 + GRADCHECK_H}, cases, mmaps, TAU[0], lam)
        fd = (hi - lo) / (2 * GRADCHECK_H)
        out[p.name] = {"ad": ad, "fd": fd, "at_unit": u0,
                       "rel_error": abs(ad - fd) / abs(fd) if fd != 0 else (0.0 if ad == 0 else math.inf)}
    return out


def unit_box(box) -> list:
    """The search box in the unit coordinate, [0, 1] per parameter (search.coarse_grid's boxes)."""
    return [SimpleNamespace(name=p.name, lo=0.0, hi=1.0) for p in box]


def grid_search(spec, box, cases, maps_for, budget: int, lam: float) -> dict:
    """The best exact evaluation on a regular grid of the unit box with at most ``budget`` points
    (``maps_for``: map_source's function, the moment maps at given values)."""
    t0 = sync_clock()
    pts = coarse_grid(unit_box(box), budget)
    best = None
    for u in pts:
        values = {p.name: p.value(u[p.name]) for p in box}
        obj = objective(hard_counts(with_values(spec, values), cases, maps_for(values)), lam)
        if best is None or obj < best[0]:
            best = (obj, values)
    return {"objective": best[0], "values": best[1], "evaluations": len(pts), "total_ms": (sync_clock() - t0) * 1e3}
