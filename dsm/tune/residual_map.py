"""A learned bias map as a residual over a global scheme: one residual per block of the light's
map, in texels, added to the scheme's signed margin (lit when ``m + rho texel_world >= 0``),
fitted exactly and chosen by cross-view validation. Plain numpy on the margins ``dsm tune``
computes; the tuning that calls it owns the scenes and schemes.

**Exact per-block fit.** Within a block each receiver turns lit at ``rho >= -m / texel_world``:
the block's errors as a function of ``rho`` are a sum of steps, minimised exactly by sorting
(the per-texel oracle's sweep, on the scheme's margins instead of the bare depth test). Among
equal optima the residual nearest 0, kept ``margin`` texels inside its interval; a block moves
only if it gains at least ``min_gain`` errors over ``rho = 0``.

**Smoothness across blocks.** A block's residual is fitted to the receivers of the
``(2 radius + 1)^2`` blocks around it (radius 0: its own), so neighbouring residuals share
evidence; it is applied to the block's own receivers only.

**Block size by validation.** Leave one training camera out: each candidate (block, radius,
min_gain) is fitted on the other training cameras and counted on the one left out, summed
over the cameras; "no residual" (the global scheme as it is) is a candidate and wins ties.
"""
from __future__ import annotations

import itertools

import numpy as np

from ..core.types import ConfigError

# a smoothed fit holds (2 radius + 1)^2 copies of every training receiver (its key, margin, unit and
# V*, about 64 bytes with the sort's work): at most this many, about 2 GB
MAX_RECEIVER_COPIES = 32_000_000
FACE_BITS = 8           # faces per map below 2^8; blocks per side below 2^16
SIDE = 1 << 16


def block_keys(texel, group, resolution, block: int, di: int = 0, dj: int = 0) -> np.ndarray:
    """Per receiver the key of the block ``(di, dj)`` blocks away from its texel's block: unique
    per map (group), face and block position (keys beyond a face's edge match no receiver)."""
    texel = np.asarray(texel, np.int64)
    R = np.asarray(resolution, np.int64)
    face, rest = texel // (R * R), texel % (R * R)
    bi, bj = rest % R // block + di, rest // R // block + dj
    return ((np.asarray(group, np.int64) << FACE_BITS | face) * SIDE + (bj + 1)) * SIDE + (bi + 1)


def fit_blocks(m, v_star, unit, keys, lam: float, margin: float) -> dict:
    """Per block (sorted ``keys``) the errors at residual 0 (``e0``), the exact least errors
    (``best``) and the residual reaching them nearest 0 (``rho``, texels)."""
    f = -np.asarray(m, np.float64) / np.asarray(unit, np.float64)      # lit iff rho >= f
    order = np.lexsort((f, keys))
    k, fs, vs = keys[order], f[order], np.asarray(v_star, bool)[order]
    new = np.r_[True, k[1:] != k[:-1]]
    start, grp = np.flatnonzero(new), np.cumsum(new) - 1
    last = np.r_[new[1:], True]
    L, S = np.cumsum(vs), np.cumsum(~vs)
    Lg, Sg = L - np.r_[0, L][start][grp], S - np.r_[0, S][start][grp]
    Ltot = np.add.reduceat(vs.astype(np.int64), start)
    # a residual just above fs[i] lights receivers 0..i of the block
    err = np.where(np.r_[fs[1:] != fs[:-1], True] | last, (Ltot[grp] - Lg) + lam * Sg, np.inf)
    nxt = np.where(last, np.inf, np.r_[fs[1:], np.inf])
    half = np.minimum(margin, 0.5 * (nxt - fs))
    rho = np.clip(0.0, fs + half, nxt - half)
    # every receiver shadowed: any residual below the block's first cut; the one nearest 0 of them
    below_err, below_rho = Ltot.astype(np.float64), np.minimum(0.0, fs[start] - margin)
    e0 = np.add.reduceat(((fs > 0) & vs) + lam * ((fs <= 0) & ~vs), start).astype(np.float64)
    best = np.minimum(np.minimum.reduceat(err, start), below_err)
    # among the optima the residual nearest 0
    cand = np.where(err == best[grp], np.abs(rho), np.inf)
    pick = np.lexsort((cand, grp))[np.r_[0, np.cumsum(np.bincount(grp))[:-1]]]
    out_rho = np.where(cand[pick] <= np.where(below_err == best, np.abs(below_rho), np.inf), rho[pick], below_rho)
    return {"keys": k[start], "e0": e0, "best": best, "rho": out_rho}


def fit_one_block(m, v_star, unit, lam: float, margin: float) -> tuple:
    """``fit_blocks`` of receivers that share one block, as (best, rho): the same numbers by the same
    arithmetic, without the per-block bookkeeping (one stable sort instead of two; the edge map's
    threshold takes hundreds of these per tune)."""
    f = -np.asarray(m, np.float64) / np.asarray(unit, np.float64)      # lit iff rho >= f
    order = np.argsort(f, kind="stable")          # lexsort((f, keys)) with one key: the same order
    fs, vs = f[order], np.asarray(v_star, bool)[order]
    L, S = np.cumsum(vs), np.cumsum(~vs)
    Ltot = L[-1]
    last = np.r_[np.zeros(fs.size - 1, bool), True]
    err = np.where(np.r_[fs[1:] != fs[:-1], True] | last, (Ltot - L) + lam * S, np.inf)
    nxt = np.r_[fs[1:], np.inf]
    half = np.minimum(margin, 0.5 * (nxt - fs))
    rho = np.clip(0.0, fs + half, nxt - half)
    below_err, below_rho = float(Ltot), np.minimum(0.0, fs[0] - margin)
    best = min(float(err.min()), below_err)
    cand = np.where(err == best, np.abs(rho), np.inf)
    # the first least candidate in sorted order (lexsort's pick: a NaN sorts last, argmin would take it)
    pick = int(np.argsort(cand, kind="stable")[0]) if np.isnan(cand).any() else int(np.argmin(cand))
    return best, (rho[pick] if cand[pick] <= (abs(below_rho) if below_err == best else np.inf) else below_rho)


def residuals(fit: dict, min_gain: float) -> np.ndarray:
    """The blocks' residuals (texels): the fitted one where it gains at least ``min_gain`` errors, else 0."""
    return np.where(fit["e0"] - fit["best"] >= min_gain, fit["rho"], 0.0)


def residual_at(fit_keys, rho, keys) -> tuple:
    """(residual per receiver, whether its block was fitted) for receivers with block ``keys``."""
    i = np.clip(np.searchsorted(fit_keys, keys), 0, max(len(fit_keys) - 1, 0))
    hit = (fit_keys[i] == keys) if len(fit_keys) else np.zeros(len(keys), bool)
    return np.where(hit, rho[i] if len(fit_keys) else 0.0, 0.0), hit


def check_budget(n_train: int, radii, source: str):
    """Refuse, before any fit, a radius whose smoothed fit would hold more than MAX_RECEIVER_COPIES
    copies of the ``n_train`` training receivers (ConfigError naming tune.bias_map.radius and the
    largest radius that fits)."""
    worst = max(radii)
    if (2 * worst + 1) ** 2 * n_train > MAX_RECEIVER_COPIES:
        fits = max(0, int(((MAX_RECEIVER_COPIES / max(n_train, 1)) ** 0.5 - 1) // 2))
        raise ConfigError(source, "tune.bias_map.radius", f"{worst} fits each block to (2 x {worst} + 1)^2 blocks: "
                          f"{(2 * worst + 1) ** 2} copies of the {n_train} training receivers, above the "
                          f"{MAX_RECEIVER_COPIES} a fit holds in memory; give radii of {fits} or less")


def smoothed_fit(rx: dict, block: int, radius: int, lam: float, margin: float) -> dict:
    """``fit_blocks`` with each block fitted to the receivers of the blocks within ``radius``
    of it; ``rx``: arrays m, v_star, unit, texel, group, resolution (per receiver)."""
    offs = list(itertools.product(range(-radius, radius + 1), repeat=2))
    keys = np.concatenate([block_keys(rx["texel"], rx["group"], rx["resolution"], block, -a, -b) for a, b in offs])
    rep = lambda x: np.tile(np.asarray(x), len(offs))
    fit = fit_blocks(rep(rx["m"]), rep(rx["v_star"]), rep(rx["unit"]), keys, lam, margin)
    own = np.unique(block_keys(rx["texel"], rx["group"], rx["resolution"], block))
    keep = np.isin(fit["keys"], own)            # blocks holding receivers of their own
    return {k: v[keep] for k, v in fit.items()}


def errors(m, v_star, lam: float) -> float:
    """acne + lambda peter-panning of margins ``m`` (lit when >= 0)."""
    lit = np.asarray(m) >= 0
    return float((~lit & v_star).sum() + lam * (lit & ~v_star).sum())


def subset(rx: dict, sel) -> dict:
    """The receivers of ``rx`` where ``sel``."""
    return {k: np.asarray(v)[sel] for k, v in rx.items()}


def apply(fit: dict, min_gain: float, rx: dict, block: int) -> tuple:
    """(margins with the residual map added, whether each receiver's block was fitted)."""
    r, hit = residual_at(fit["keys"], residuals(fit, min_gain), block_keys(rx["texel"], rx["group"], rx["resolution"],
                                                                     block))
    return np.asarray(rx["m"], np.float64) + r * np.asarray(rx["unit"], np.float64), hit


def choose(rx: dict, camera, blocks, radii, gains, lam: float, margin: float) -> dict:
    """Leave one training camera out: per candidate (block, radius, min_gain) the summed errors on
    each camera's receivers of the fit to the others'; "none" (no residual) wins ties. The
    candidates' scores and the chosen one (None: no residual)."""
    camera = np.asarray(camera)
    cams = sorted(set(camera.tolist()))
    none = errors(rx["m"], rx["v_star"], lam)
    scores = {}
    for block, radius in itertools.product(blocks, radii):
        folds = []
        for cam in cams:
            fit = smoothed_fit(subset(rx, camera != cam), block, radius, lam, margin)
            folds.append((fit, subset(rx, camera == cam)))
        for g in gains:
            scores[(block, radius, g)] = sum(errors(apply(fit, g, out, block)[0], out["v_star"], lam)
                                             for fit, out in folds)
    best = min(scores, key=lambda c: (scores[c], -c[2], -c[1], -c[0])) if scores else None
    chosen = best if best is not None and scores[best] < none else None
    return {"none": none, "scores": [{"block": b, "radius": r, "min_gain": g, "errors": e}
                                     for (b, r, g), e in scores.items()], "chosen": chosen}
