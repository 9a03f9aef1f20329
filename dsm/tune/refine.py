"""Exact refinement around the best point: line searches on linearised margins and a compass search."""
from __future__ import annotations


import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline as pl
from ..schemes import get as get_scheme
from .relax import margins
from .evaluate import count, sync_clock


def margin_line(module, params, values: dict, direction: dict, cases, groups) -> tuple:
    """Every receiver's exact (nearest-lookup) margin at ``values`` and its derivative along
    ``direction`` (parameter name -> change per unit step, in the parameter's unit), by Dr.Jit's
    forward-mode AD: (margin, slope), float64 arrays over the cases in order."""
    culling = pl.culling_of(params)
    count("line")
    m_all, g_all = [], []
    for c in cases:
        a = mi.Float(0.0)
        dr.enable_grad(a)
        vals = {k: dr.opaque(mi.Float, float(v)) + a * dr.opaque(mi.Float, float(direction.get(k, 0.0)))
                for k, v in values.items()}
        m = margins(module, params, vals, c.rx, groups[c.group].maps[culling], relax=False)
        dr.forward(a)
        m_all.append(np.asarray(dr.detach(m).numpy(), np.float64))
        g_all.append(np.asarray(dr.grad(m).numpy(), np.float64))
    return np.concatenate(m_all), np.concatenate(g_all)


def line_objective(m, g, v_star, lam, a_lo: float, a_hi: float, nearest: bool = False) -> tuple:
    """The exact objective of margins that are affine in a step ``a`` (``m + a g``), at its best
    over ``[a_lo, a_hi]``: each receiver flips at ``a = -m / g``; counted at the ends and at the
    midpoints between consecutive flips by sorted counts (the threshold sweep of the exact
    oracles, along any line). (best step, its objective); ties: the widest interval's midpoint,
    or with ``nearest`` the best candidate nearest ``a_lo``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        flip = -m / g
    up, down, flat = g > 0, g < 0, g == 0
    inside = np.sort(flip[(up | down) & (flip > a_lo) & (flip < a_hi)])
    edges = np.unique(np.concatenate([[a_lo], inside, [a_hi]]))
    cands = np.concatenate([[a_lo], 0.5 * (edges[:-1] + edges[1:]), [a_hi]]) if len(edges) > 1 else edges
    width = np.concatenate([[0.0], np.diff(edges), [0.0]]) if len(edges) > 1 else np.zeros(1)
    err = np.zeros(len(cands))
    for sel, lit_when_above in ((up, True), (down, False)):
        for truth, weight in ((True, 1.0), (False, lam)):
            th = np.sort(flip[sel & (v_star == truth)])
            # lit iff a >= flip (g > 0) or a <= flip (g < 0); an error when lit differs from the truth
            n_lit = np.searchsorted(th, cands, "right") if lit_when_above else len(th) - np.searchsorted(th, cands, "left")
            err += weight * ((len(th) - n_lit) if truth else n_lit)
    err += float(((m[flat] < 0) & v_star[flat]).sum() + lam * ((m[flat] >= 0) & ~v_star[flat]).sum())
    obj = err / max(m.size, 1)
    best = np.flatnonzero(obj == obj.min())
    i = best[0] if nearest else best[np.argmax(width[best])]
    return float(cands[i]), float(obj[i])


def line_reach(module, spec, values: dict, name: str, lo, scale: float, train, groups, lam) -> float:
    """The value of parameter ``name`` (others at ``values``) where the exact objective is least
    along the whole line from ``lo`` up (None: a parameter without a minimum, from a texel's worth
    below the first flip), under the receivers' margins linearised there (forward AD; exact where
    the margin is affine in it, as for every constant-like term): the least such value of the
    optimal flips, which a search box must hold (``scale``: one texel's worth in the parameter's
    unit, how far past the last flip the line is counted). NaN where no receiver flips."""
    m, g = margin_line(module, spec.params, values, {name: 1.0}, train, groups)
    with np.errstate(divide="ignore", invalid="ignore"):
        flip = values[name] - m / g
    flip = flip[np.isfinite(flip) & (flip > (-np.inf if lo is None else lo))]
    if flip.size == 0:
        return float("nan")
    if lo is None:                    # the best may be a negative offset (a large lambda prefers acne)
        lo = min(float(flip.min()) - scale, 0.0)
    v_star = np.concatenate([c.v_star for c in train])
    a_hi = float(flip.max()) - values[name] + scale        # a texel's worth past the last flip
    a, _ = line_objective(m, g, v_star, lam, lo - values[name], a_hi, nearest=True)
    return values[name] + a


def line_search(module, spec, box, best, train, groups, lam, p) -> dict:
    """The exact objective's best along parameter ``p`` from ``best``'s values, under the
    receivers' margins linearised in that parameter (forward AD), within ``p``'s range: the
    point to evaluate (exact for a margin affine in the parameter: constant, receiver plane,
    adaptive; a candidate to check otherwise) and the objective the linearisation predicts there."""
    vals = best[1]
    m, g = margin_line(module, spec.params, vals, {p.name: 1.0}, train, groups)
    v_star = np.concatenate([c.v_star for c in train])
    a, predicted = line_objective(m, g, v_star, lam, p.lo - vals[p.name], p.hi - vals[p.name])
    return {**vals, p.name: min(max(vals[p.name] + a, p.lo), p.hi)}, predicted


def exact_refinement(spec, box, best, train, groups, lam, exact, budget: int, cells: int) -> dict:
    """At most ``budget`` exact evaluations around ``best``: a compass search (keeping two per
    parameter back), exact line searches along each parameter until a round gains nothing, and
    the compass search again with what is left. {best, evaluations: (phase, values, objective), ms}."""
    t0, out = sync_clock(), []
    ref = compass_search(box, exact, best, max(budget - 2 * len(box), 0), cells)
    out += [("refine", v, o) for v, o in ref["evaluations"]]
    best, seen, improved = ref["best"], set(), True
    while improved and len(out) < budget:     # exact line searches along each parameter
        improved = False
        for p in box:
            if len(out) >= budget:
                break
            vals, predicted = line_search(get_scheme(spec.name), spec, box, best, train, groups, lam, p)
            key = tuple(vals[q.name] for q in box)
            if key in seen or predicted >= best[0]:     # the model is exact at the current point: no gain
                continue
            seen.add(key)
            out.append(("line", vals, exact(vals)))
            if out[-1][2] < best[0]:
                best, improved = (out[-1][2], vals), True
    ref = compass_search(box, exact, best, budget - len(out), cells)
    out += [("refine", v, o) for v, o in ref["evaluations"]]
    return {"best": ref["best"], "evaluations": out, "ms": (sync_clock() - t0) * 1e3}


def compass_search(box, exact, best, budget: int, cells: int) -> dict:
    """Compass (pattern) search on the exact objective from ``best`` = (objective, values), at most
    ``budget`` new evaluations: each parameter is tried one step up and down (clipped to its
    range; a point already evaluated is not evaluated again), a strict improvement moves there,
    and a poll with none halves every step. First step: half a coarse-grid cell (``cells``
    points per parameter). Hooke & Jeeves, "Direct search solution of numerical and
    statistical problems", J. ACM 1961; Kolda, Lewis & Torczon, SIAM Review 2003 (compass search).
    The exact objective is piecewise constant, so its gradient is 0 almost everywhere: near the
    relaxed loss's optimum only a direct search on the exact objective can pick its best step."""
    steps = {p.name: (p.hi - p.lo) / cells / 2.0 for p in box}
    seen = {tuple(best[1][p.name] for p in box)}
    evaluations, t0 = [], sync_clock()
    while len(evaluations) < budget and any(v > 0 for v in steps.values()):
        moved = False
        for p in box:
            for sign in (1.0, -1.0):
                if len(evaluations) >= budget:
                    break
                vals = dict(best[1])
                vals[p.name] = min(max(best[1][p.name] + sign * steps[p.name], p.lo), p.hi)
                key = tuple(vals[q.name] for q in box)
                if key in seen:
                    continue
                seen.add(key)
                obj = exact(vals)
                evaluations.append((vals, obj))
                if obj < best[0]:
                    best, moved = (obj, vals), True
                    break
        if not moved:
            steps = {k: v / 2.0 for k, v in steps.items()}
            if max(s / (p.hi - p.lo) for p, s in zip(box, steps.values())) < 1e-7:
                break                # below float32 resolution of the box: nothing left to find
    return {"best": best, "evaluations": evaluations, "ms": (sync_clock() - t0) * 1e3}
