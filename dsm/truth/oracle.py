"""The best any bias can do: exact oracles of a nearest-lookup shadow map (pure numpy).

One objective everywhere: ``E(lambda) = (n_acne + lambda n_peterpan) / n_receivers``.

**Thresholds.** A receiver r of depth ``d`` whose nearest texel (its own lookup point, no
shift) holds ``z1`` is lit by a depth bias ``b`` when the kit's float32 comparison
``(z1 + b) - d >= 0`` holds (``constant``'s margin). It is monotone in ``b``, so there is a
smallest float32 ``tau_r`` for which it holds: lit exactly when ``b >= tau_r``. A truly lit
receiver needs ``b >= tau_r``; a truly shadowed one ``b < tau_r``. In texel units (``b = k
texel_world(r)``, the product rounded to float32 as the lookup's ``resolve`` does) the
threshold ``kappa_r`` is the smallest float32 ``k`` with ``(z1 + fl(k texel_world)) - d >= 0``.

Both are first tried where the comparison turns in float64 (the midpoint of ``d`` and the float32
below it, less ``z1``; ``kappa`` from ``tau``'s midpoint ``/ texel_world``): the float32 there or one
either side is the threshold where it holds there and fails just below. Where none does, the
float64 estimate ``d - z1`` (``/ texel_world``) starts a bisection over the ordered float32
values. A monotone comparison turns at one float32, so both ways give the same answer; each is
checked against the comparison itself: it holds at the threshold and fails at the next float32
below it (``np.nextafter``).

**Oracles.** With thresholds sorted, the counts at every bias at once are cumulative counts:
``acne(b) = #{truly lit, tau > b}``, ``peterpan(b) = #{truly shadowed, tau <= b}``. The curve
is piecewise constant; it changes only at the thresholds, so the candidates are the distinct
thresholds and one bias below all of them (every receiver shadowed: reported as the float32
just below the smallest threshold). Among equal optima the smallest candidate wins.

- world oracle: one ``b`` for the map; texel oracle: one ``k`` for the map;
- per-texel oracle: a world ``b`` chosen separately in each texel (the same search within each
  texel's receivers). No scheme whose bias is a function of the texel alone (constant and
  slope-scaled in world or range units, midpoint, dual) can beat it: its objective is the
  share of the error that is the map's resolution's, not the bias's.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

F32 = np.float32


def lit_world(z1, d, b) -> np.ndarray:
    """The kit's comparison with a world bias, in float32: ``(z1 + b) - d >= 0``."""
    z1, d, b = (np.asarray(x, F32) for x in (z1, d, b))
    with np.errstate(over="ignore", invalid="ignore"):
        return ((z1 + b) - d) >= F32(0)


def lit_texel(z1, d, tw, k) -> np.ndarray:
    """The comparison with ``b = fl(k texel_world)`` (``resolve`` multiplies in float32)."""
    z1, d, tw, k = (np.asarray(x, F32) for x in (z1, d, tw, k))
    with np.errstate(over="ignore", invalid="ignore"):
        return ((z1 + k * tw) - d) >= F32(0)


def _key(x: np.ndarray) -> np.ndarray:
    """float32 -> int64 preserving order (the sign-magnitude bits made two's complement)."""
    i = np.asarray(x, F32).view(np.int32).astype(np.int64)
    return np.where(i < 0, -(i & 0x7FFFFFFF), i)


def _unkey(k: np.ndarray) -> np.ndarray:
    k = np.asarray(k, np.int64)
    i = np.where(k < 0, (-k) | 0x80000000, k).astype(np.uint32)
    return i.view(np.int32).view(F32)


def _smallest(holds, est: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per element, the smallest float32 x for which the monotone ``holds(x, mask)`` is true,
    searched around the float64 estimate ``est`` (``scale``: the size of its error)."""
    n = est.size
    step = np.maximum(np.abs(scale), 1e-30) * 2.0 ** -20
    lo = np.full(n, -np.inf)
    hi = np.full(n, np.inf)
    # bracket: grow a window around the estimate until it holds above and fails below
    w = step.copy()
    todo_hi, todo_lo = np.ones(n, bool), np.ones(n, bool)
    for _ in range(200):
        if todo_hi.any():
            x = (est + w).astype(F32)
            ok = holds(x, todo_hi)
            set_ = todo_hi & ok
            hi[set_] = x[set_]
            todo_hi &= ~ok
        if todo_lo.any():
            x = (est - w).astype(F32)
            ok = holds(x, todo_lo)
            set_ = todo_lo & ~ok
            lo[set_] = x[set_]
            todo_lo &= ok
        if not (todo_hi.any() or todo_lo.any()):
            break
        w = w * 4.0
    lo = np.where(np.isinf(lo), F32(-np.finfo(F32).max), lo)
    hi = np.where(np.isinf(hi), F32(np.finfo(F32).max), hi)
    klo, khi = _key(lo.astype(F32)), _key(hi.astype(F32))     # holds(hi) true, holds(lo) false
    while True:
        open_ = khi - klo > 1
        if not open_.any():
            break
        mid = klo + (khi - klo) // 2
        ok = holds(_unkey(mid), open_)
        khi = np.where(open_ & ok, mid, khi)
        klo = np.where(open_ & ~ok, mid, klo)
    return _unkey(khi)


def _below(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, F32(-np.inf)).astype(F32)


def _at_guess(holds, guess: np.ndarray) -> tuple:
    """(x, found): per element the float32 nearest the float64 ``guess`` or one either side at which
    the monotone ``holds(x)`` turns true (it holds there and fails at the float32 below), where one does."""
    with np.errstate(over="ignore", invalid="ignore"):
        c = np.asarray(guess, np.float64).astype(F32)
    c1 = _below(c)
    c2, c3 = _below(c1), np.nextafter(c, F32(np.inf)).astype(F32)
    h2, h1, h, h3 = holds(c2), holds(c1), holds(c), holds(c3)
    turn1, turn, turn3 = h1 & ~h2, h & ~h1, h3 & ~h
    return np.where(turn1, c1, np.where(turn, c, c3)), turn1 | turn | turn3


def _smallest_from(holds, guess, est, scale) -> np.ndarray:
    """:func:`_smallest` of ``holds(x, idx)`` (``x`` for the elements ``idx``), first tried at ``guess``
    (:func:`_at_guess`): monotone ``holds`` turns true at one float32 only, so the answer is the same;
    the bisection runs on the elements the guess misses (non-finite inputs, a guess rounded off)."""
    x, found = _at_guess(lambda v: holds(v, slice(None)), guess)
    x[x == 0] = 0.0                     # -0 as +0: the bisection's ordered keys know one zero, +0
    miss = np.flatnonzero(~found)
    if miss.size:
        x[miss] = _smallest(lambda v, m: holds(v, miss) | ~m, est[miss], scale[miss])
    return x


def _world_guess(z1, d) -> np.ndarray:
    """Where ``fl(z1 + b) >= d`` starts in float64: the midpoint of ``d`` and the float32 below it, less ``z1``."""
    with np.errstate(over="ignore", invalid="ignore"):
        return (_below(d).astype(np.float64) + d.astype(np.float64)) / 2 - z1.astype(np.float64)


def thresholds(z1, d) -> np.ndarray:
    """Per receiver the smallest float32 world bias ``tau`` with ``(z1 + tau) - d >= 0`` (float32)."""
    z1, d = np.asarray(z1, F32), np.asarray(d, F32)
    est = d.astype(np.float64) - z1.astype(np.float64)
    scale = np.maximum(np.abs(z1), np.abs(d)).astype(np.float64)
    tau = _smallest_from(lambda x, i: lit_world(z1[i], d[i], x), _world_guess(z1, d), est, scale)
    check(lit_world, (z1, d), tau)
    return tau


def texel_thresholds(z1, d, tw, tau=None) -> np.ndarray:
    """Per receiver the smallest float32 ``k`` with ``(z1 + fl(k texel_world)) - d >= 0``; ``tau``: the
    world thresholds of the same ``z1`` and ``d`` (:func:`thresholds`) where the caller has them."""
    z1, d, tw = np.asarray(z1, F32), np.asarray(d, F32), np.asarray(tw, F32)
    twd = np.maximum(tw.astype(np.float64), 1e-300)
    est = (d.astype(np.float64) - z1.astype(np.float64)) / twd
    scale = np.maximum(np.abs(z1), np.abs(d)).astype(np.float64) / twd
    # fl(k tw) must reach the world threshold tau: k from the midpoint of tau and the float32 below it
    tau = thresholds(z1, d) if tau is None else np.asarray(tau, F32)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        guess = (_below(tau).astype(np.float64) + tau.astype(np.float64)) / 2 / tw.astype(np.float64)
    kappa = _smallest_from(lambda x, i: lit_texel(z1[i], d[i], tw[i], x), guess, est, scale)
    check(lambda z, dd, t, x: lit_texel(z, dd, tw, x), (z1, d, None), kappa)
    return kappa


def check(lit, args, t):
    """The comparison holds at each threshold and fails at the float32 just below it."""
    below = np.nextafter(t, F32(-np.inf)).astype(F32)
    if not (lit(*args, t).all() and not lit(*args, below).any()):
        raise AssertionError("oracle thresholds disagree with the kit's float32 comparison")


# ---------------------------------------------------------------- one bias for the map

@dataclass
class Curve:
    """The exact counts against one bias for the map: at ``b[i]`` (and up to, not including,
    ``b[i + 1]``) ``acne[i]`` false shadows and ``peterpan[i]`` false lights."""
    b: np.ndarray
    acne: np.ndarray
    peterpan: np.ndarray
    n_lit: int
    n_shadowed: int

    def at(self, b) -> tuple:
        """(n_acne, n_peterpan) at bias value(s) ``b`` (float32 as the lookup reads it)."""
        b = np.asarray(b, F32)
        i = np.searchsorted(self.b, b, side="right") - 1
        i = np.clip(i, 0, self.b.size - 1)
        return self.acne[i], self.peterpan[i]

    def objective(self, lam: float, n: int) -> np.ndarray:
        """E(lambda) = (n_acne + lam n_peterpan) / n at each bias of ``b``; NaN when ``n`` is 0."""
        return (self.acne + lam * self.peterpan) / n if n else np.full(self.b.size, np.nan)


def curve(t: np.ndarray, v_star: np.ndarray) -> Curve:
    """The exact curve of a single bias (thresholds ``t``, truth ``v_star``), over every
    distinct threshold and one value below them all."""
    t = np.asarray(t, F32)
    v_star = np.asarray(v_star, bool)
    tl, ts = np.sort(t[v_star]), np.sort(t[~v_star])
    cand = np.unique(t)
    bottom = np.nextafter(cand[0], F32(-np.inf)) if cand.size else F32(0)
    cand = np.concatenate([[bottom], cand]).astype(F32)
    acne = tl.size - np.searchsorted(tl, cand, side="right")
    peter = np.searchsorted(ts, cand, side="right")
    return Curve(cand, acne.astype(np.int64), peter.astype(np.int64), int(tl.size), int(ts.size))


def best(c: Curve, lam: float, n: int) -> dict:
    """The smallest bias minimizing E(lambda) on a curve: its value and counts."""
    obj = c.acne + lam * c.peterpan
    i = int(np.argmin(obj))                 # the first: the smallest among equal optima
    return {"b": float(c.b[i]), "n_acne": int(c.acne[i]), "n_peterpan": int(c.peterpan[i]),
            "objective": float(obj[i]) / n if n else float("nan")}


# ---------------------------------------------------------------- one bias per texel

def per_texel(tau, v_star, texel, lam: float) -> dict:
    """The best world bias chosen separately in each texel (smallest among equal optima).

    Returns the counts, the objective and per receiver ``wrong`` (misclassified even so: the
    resolution's share of the errors) and ``b`` (its texel's chosen bias; -inf: all shadowed)."""
    tau = np.asarray(tau, F32)
    v_star = np.asarray(v_star, bool)
    texel = np.asarray(texel, np.int64)
    n = tau.size
    if n == 0:
        return {"n_acne": 0, "n_peterpan": 0, "objective": float("nan"), "wrong": np.zeros(0, bool),
                "b": np.zeros(0, F32)}
    order = np.lexsort((tau, texel))
    tx, ts, lit = texel[order], tau[order], v_star[order]
    start = np.flatnonzero(np.r_[True, tx[1:] != tx[:-1]])
    group = np.cumsum(np.r_[True, tx[1:] != tx[:-1]]) - 1
    L = np.cumsum(lit)
    S = np.cumsum(~lit)
    L0 = np.r_[0, L][start][group]           # before the group
    S0 = np.r_[0, S][start][group]
    Lg, Sg = L - L0, S - S0                  # inclusive counts within the group
    Ltot = np.add.reduceat(lit.astype(np.int64), start)
    # a candidate is the end of a run of equal thresholds within a texel
    run_end = np.r_[(tx[1:] != tx[:-1]) | (ts[1:] != ts[:-1]), True]
    obj = np.where(run_end, (Ltot[group] - Lg) + lam * Sg, np.inf)
    bottom = Ltot.astype(np.float64)         # every receiver of the texel shadowed
    gmin = np.minimum(np.minimum.reduceat(obj, start), bottom)
    hit = np.flatnonzero(obj == gmin[group])
    first = np.full(start.size, -1)
    g_hit, idx = np.unique(group[hit], return_index=True)
    first[g_hit] = hit[idx]
    use_bottom = bottom <= gmin              # ties: the bottom is the smallest bias
    b_t = np.where(use_bottom | (first < 0), -np.inf, ts[np.maximum(first, 0)].astype(np.float64)).astype(F32)
    b_sorted = b_t[group]
    lit_sorted = ts <= b_sorted
    wrong_sorted = lit_sorted != lit
    wrong = np.empty(n, bool)
    wrong[order] = wrong_sorted
    b = np.empty(n, F32)
    b[order] = b_sorted
    n_acne = int((wrong & v_star).sum())
    n_pp = int((wrong & ~v_star).sum())
    return {"n_acne": n_acne, "n_peterpan": n_pp, "objective": (n_acne + lam * n_pp) / n, "wrong": wrong, "b": b}


# ---------------------------------------------------------------- all three

def oracles(tau, kappa, v_star, texel, lam: float = 1.0) -> dict:
    """The world, texel and per-texel oracles of one map and stored format at one lambda, with
    their exact curves (``curve_world``, ``curve_texel``) and the per-texel ``wrong`` mask."""
    v_star = np.asarray(v_star, bool)
    n = int(v_star.size)
    cw, ck = curve(tau, v_star), curve(kappa, v_star)
    w, k = best(cw, lam, n), best(ck, lam, n)
    pt = per_texel(tau, v_star, texel, lam)
    n_lit, n_sh = int(v_star.sum()), int((~v_star).sum())
    rate = lambda a, b: a / b if b else float("nan")
    row = {"lambda": float(lam), "n_receivers": n, "n_gt_lit": n_lit, "n_gt_shadowed": n_sh,
           "best_b": w["b"], "best_k": k["b"]}
    for tag, o in (("world", w), ("texel", k), ("per_texel", pt)):
        row[f"{tag}_objective"] = o["objective"]
        row[f"{tag}_n_acne"] = o["n_acne"]
        row[f"{tag}_n_peterpan"] = o["n_peterpan"]
        row[f"{tag}_acne_rate"] = rate(o["n_acne"], n_lit)
        row[f"{tag}_peterpan_rate"] = rate(o["n_peterpan"], n_sh)
    return {"row": row, "curve_world": cw, "curve_texel": ck, "wrong": pt["wrong"]}
