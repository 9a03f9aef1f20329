"""The tuner's references: a grid search with the same budget, an exact 1-D scan, a gradient check."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..report.tables import objective
from ..schemes import get as get_scheme
from ..core.types import SchemeSpec
from .evaluate import NAN, hard_counts, sync_clock, with_values
from .relax import relaxed_loss, relaxed_loss_np


def grid_search(tc, spec: SchemeSpec, box, train, groups, budget: int) -> dict:
    """The best hard training objective over a regular grid of the same box with at most
    ``budget`` evaluations (points per parameter: floor(budget^(1/p)))."""
    p = len(box)
    k = max(1, int(math.floor(budget ** (1.0 / p) + 1e-9)))
    # one point a parameter (steps < 2^p): the box's centre, not its lower corner
    axes = [np.linspace(b.lo, b.hi, k) if k > 1 else np.array([0.5 * (b.lo + b.hi)]) for b in box]
    best, evals = None, 0
    t0 = sync_clock()
    for combo in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, p):
        vals = {b.name: float(x) for b, x in zip(box, combo)}
        obj = objective(hard_counts(with_values(spec, vals), train, groups), tc.spec.lam)
        evals += 1
        if best is None or obj < best[0]:
            best = (obj, vals)
    ms = (sync_clock() - t0) * 1e3
    return {"values": best[1], "objective": best[0], "evaluations": evals, "points_per_parameter": k,
            "total_ms": ms}


def exact_scan(tc, spec: SchemeSpec, box, train, groups, points: int) -> dict | None:
    """A one-parameter scheme's exact training objective at ``points`` evenly spaced values of its
    search range, ends included (the reference the tuner is held to; for a constant bias, the
    oracle's curve sampled); None for a scheme tuning more than one parameter."""
    if len(box) != 1 or points < 1:
        return None
    b = box[0]
    best, t0 = None, sync_clock()
    for x in np.linspace(b.lo, b.hi, points):
        obj = objective(hard_counts(with_values(spec, {b.name: float(x)}), train, groups), tc.spec.lam)
        if best is None or obj < best[0]:
            best = (obj, {b.name: float(x)})
    return {"values": best[1], "objective": best[0], "evaluations": points, "total_ms": (sync_clock() - t0) * 1e3}


GRADCHECK_STEP = 0.01      # texels' worth: the central difference's half step


def gradient_check(tc, spec: SchemeSpec, box, train, groups) -> dict:
    """Per tuned parameter at the start: the relaxed loss's derivative by Dr.Jit AD (all
    parameters differentiated together) against a central difference of the same loss computed
    in numpy float64 from the kit's forward margins, at the first temperature; half step
    ``GRADCHECK_STEP`` texels' worth in the parameter's unit. {name: {ad, fd, rel_error}}."""
    ts, mod = tc.spec, get_scheme(spec.name)
    start = {p.name: p.start for p in box}
    x = {p.name: mi.Float(float(p.start)) for p in box}
    for v in x.values():
        dr.enable_grad(v)
    loss, _ = relaxed_loss(mod, spec.params, x, train, groups, ts.temperature[0], ts.lam)
    dr.backward(loss)
    out = {}
    for p in box:
        h = GRADCHECK_STEP * p.scale
        f = lambda v: relaxed_loss_np(mod, spec.params, {**start, p.name: v}, train, groups, ts.temperature[0], ts.lam)
        lo, mid, hi = f(p.start - h), f(p.start), f(p.start + h)
        ad = float(dr.grad(x[p.name]).numpy().ravel()[0])
        fine = central(f(p.start - h / FINE), f(p.start + h / FINE), h / FINE, ad)
        out[p.name] = {"ad": ad, **differences(lo, mid, hi, h, ad), "fd_fine": fine["fd"],
                       "rel_error_fine": fine["rel_error"]}
    return out


FINE = 4    # the second central difference's step is the first's over FINE


def central(lo: float, hi: float, h: float, ad: float) -> dict:
    """The central difference of f(x - h), f(x + h) and its relative error against ``ad``. Where a
    loss sums many receivers each bending somewhere (a bilinear z1 at texel centres), the share a
    step straddles shrinks with the step: a relative error that falls as h does is the step's, not AD's."""
    fd = (hi - lo) / (2 * h)
    return {"fd": fd, "rel_error": abs(ad - fd) / abs(fd) if fd else NAN}


KINK_RATIO = 0.1    # one-sided differences further apart than this (relative): a kink within the step


def differences(lo: float, mid: float, hi: float, h: float, ad: float) -> dict:
    """The central difference of f(x - h), f(x), f(x + h) against ``ad`` (rel_error), and the one-sided
    differences: where they disagree by more than KINK_RATIO the loss has a kink (a max, a clamp)
    within the step, so the central difference straddles two slopes and says nothing of AD."""
    left, right = (mid - lo) / h, (hi - mid) / h
    scale = max(abs(left), abs(right))
    return {**central(lo, hi, h, ad), "left": left, "right": right,
            "kink": bool(scale > 0 and abs(right - left) > KINK_RATIO * scale)}
