"""A learned bias map predicted from the shadow map around each receiver (``fit = "edge"``): a few
weights shared by every texel, fitted exactly on the training receivers. Plain numpy on the margins
``dsm tune`` computes (dsm.tune.bias_map.neighbour_margins); the tuning that calls it owns the scenes.

**Why.** The errors the best tuned global scheme leaves all sit where the 2 x 2 texels around a
receiver disagree (a depth discontinuity: an occluder's edge or a silhouette inside the texel), one
or two per texel, and not where the held-out views look again: a free bias per block (Adam, or the
exact residual of dsm.tune.residual_map) learns those texels and does not generalize. Which side of
an edge a receiver lies on is what the map's neighbourhood tells, in every view alike.

**Model.** Each of the 3 x 3 texels around the receiver's lookup point (the base scheme's shifted
point, its texel at the centre) gives the base scheme's margin with that texel's z1, ``m_k``,
clipped to a signed vote ``s_k = clip(m_k / (clip texel_world), -1, 1)``. The votes are averaged
with a tent of half-width ``width`` texels centred on the receiver's position (width 1: bilinear,
the 2 x 2 around it), giving a score in [-1, 1]; the receiver is lit when
``score >= threshold + grazing (1 - cos)``, ``cos`` its normal's cosine to the light. Where every
vote agrees the score is +-1 and the base scheme's answer stands (the map changes nothing away
from edges); at an edge the neighbourhood decides, and a receiver at a grazing angle needs more
lit votes. Equivalently, a per-receiver bias that raises or lowers the base margin only where the
neighbourhood shows a discontinuity.

**Fit.** For each candidate (width, clip, grazing) the threshold is exact: lit is a step in it,
so the training errors as a function of the threshold are minimised by one sort (the per-texel
oracle's sweep, dsm.tune.residual_map.fit_blocks with one block), the optimum nearest 0 kept
``THRESHOLD_MARGIN`` inside its interval; the candidate with the fewest training errors wins
(ties: less grazing, width nearer 1, larger clip). Three shape parameters and one threshold over
every training receiver: nothing fitted to a view is per texel, so nothing is left to memorise it.

**Per-texel offsets** (``samples`` > 0). The shared threshold places an edge inside a texel where
the tent's interpolation of the taps puts it; the light's own rays through the texel
(dsm.tune.light_samples, ``samples`` x ``samples`` a texel, every surface they meet) say where it
passes. Per texel an offset ``r`` is fitted exactly to those samples (lit where ``score - needed +
r >= 0``; the same sort per texel, the optimum nearest 0, so near 0 wherever the shared threshold
is already best): one number per texel, fitted to the scene and light rather than to a view, so it
carries to views no training camera saw.
"""
from __future__ import annotations

import itertools

import numpy as np

from .residual_map import fit_blocks, fit_one_block, residual_at

OFFSETS = tuple((a, b) for b in (-1, 0, 1) for a in (-1, 0, 1))   # the 3 x 3 taps, (i, j) texels; centre 4
THRESHOLD_MARGIN = 0.02           # score units kept inside the threshold's optimal interval


def tent_score(m9, fx, fy, texel_world, width: float, clip: float) -> np.ndarray:
    """Per receiver the tent-weighted mean of the clipped votes of its 3 x 3 taps' margins ``m9``
    (world units, columns in ``OFFSETS`` order); ``fx, fy``: the receiver's position from its
    texel's centre (texels, in [-0.5, 0.5)); ``clip`` in texels."""
    m9 = np.asarray(m9, np.float64)
    votes = np.clip(m9 / (clip * np.asarray(texel_world, np.float64)[:, None]), -1.0, 1.0)
    num = np.zeros(m9.shape[0])
    den = np.zeros(m9.shape[0])
    for k, (a, b) in enumerate(OFFSETS):
        w = np.maximum(0.0, 1.0 - np.abs(a - fx) / width) * np.maximum(0.0, 1.0 - np.abs(b - fy) / width)
        num += w * votes[:, k]
        den += w
    return num / den


def needed(score, cos, grazing: float) -> np.ndarray:
    """The score each receiver needs above the threshold: ``score - grazing (1 - cos)``."""
    return np.asarray(score, np.float64) - grazing * (1.0 - np.clip(np.asarray(cos, np.float64), 0.0, 1.0))


def exact_threshold(x, v_star, lam: float) -> tuple:
    """(threshold, errors): the threshold ``t`` minimising acne + lambda peter-panning of "lit iff
    x >= t" exactly (the optimum nearest 0, ``THRESHOLD_MARGIN`` inside its interval)."""
    x = np.asarray(x, np.float64)
    # fit_blocks (one block) lights a receiver where rho >= -m / unit: rho = -t, m = x, unit = 1
    best, rho = fit_one_block(x, v_star, np.ones_like(x), lam, THRESHOLD_MARGIN)
    return -float(rho), float(best)


def lit(rx: dict, model: dict) -> np.ndarray:
    """Whether each receiver of ``rx`` (arrays m9, fx, fy, unit, cos) is lit under ``model``."""
    s = tent_score(rx["m9"], rx["fx"], rx["fy"], rx["unit"], model["width"], model["clip"])
    return needed(s, rx["cos"], model["grazing"]) >= model["threshold"]


def tent_scores(rx: dict, widths, clips) -> dict:
    """Each (width, clip) candidate's tent score of every receiver of ``rx`` (arrays m9, fx, fy, unit)."""
    return {(w, c): tent_score(rx["m9"], rx["fx"], rx["fy"], rx["unit"], w, c)
            for w, c in itertools.product(widths, clips)}


def fit(rx: dict, widths, clips, grazings, lam: float, tents: dict | None = None) -> dict:
    """The model (width, clip, grazing, threshold) with the fewest training errors over the
    candidates, and every candidate's score (``rx``: arrays m9, fx, fy, unit, cos, v_star;
    ``tents``: their tent_scores when already made, then only cos and v_star are read)."""
    v = np.asarray(rx["v_star"], bool)
    tents = tent_scores(rx, widths, clips) if tents is None else tents
    scores = []
    for width, clip in itertools.product(widths, clips):
        s = tents[(width, clip)]
        for g in grazings:
            t, e = exact_threshold(needed(s, rx["cos"], g), v, lam)
            scores.append({"width": float(width), "clip": float(clip), "grazing": float(g), "threshold": t,
                           "errors": e})
    best = min(scores, key=lambda c: (c["errors"], c["grazing"], abs(c["width"] - 1.0), -c["clip"]))
    return {**best, "scores": scores}


# ---------------------------------------------------------------- per-texel offsets (light samples)

def over_threshold(rx: dict, model: dict) -> np.ndarray:
    """Each receiver's score less what it needs under ``model``: lit where at least 0 (before offsets)."""
    s = tent_score(rx["m9"], rx["fx"], rx["fy"], rx["unit"], model["width"], model["clip"])
    return needed(s, rx["cos"], model["grazing"]) - model["threshold"]


def fit_offsets(x, v_star, keys, lam: float) -> tuple:
    """Per texel (``keys``, one per receiver) the offset ``r`` minimising its receivers' acne + lambda
    peter-panning of "lit iff x + r >= 0" exactly (the optimum nearest 0, ``THRESHOLD_MARGIN`` inside its
    interval: within that of 0 wherever 0 is optimal): (sorted keys, offsets)."""
    x = np.asarray(x, np.float64)
    fit = fit_blocks(x, v_star, np.ones_like(x), np.asarray(keys, np.int64), lam, THRESHOLD_MARGIN)
    return fit["keys"], fit["rho"]


def offset_at(keys_fit, offsets, keys) -> np.ndarray:
    """The offset of each receiver's texel (``keys``), 0 for a texel no light sample fell in."""
    return residual_at(keys_fit, offsets, keys)[0]
