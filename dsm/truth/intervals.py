"""Confidence intervals of a Monte Carlo visible fraction drawn in independent replicates.

The area-light reference (:func:`dsm.truth.area.reference`) draws each receiver's samples as ``B``
independent replicates, each a jittered stratified set over the light (randomized quasi-Monte
Carlo: every replicate an unbiased estimate, the replicates independent of one another). The
interval comes from the replicates' spread (Student's t with ``B - 1`` degrees of freedom; the
RQMC interval of L'Ecuyer & Lemieux, "Recent advances in randomized quasi-Monte Carlo methods",
2002), which is far tighter than a binomial bound: stratification makes the samples anything
but independent coin flips.

Where every sample agrees (none or all of ``n`` visible) the spread is zero and says nothing.
There the bound is the one-sided Clopper-Pearson bound of a zero count, ``1 - (1 - c)^(1/n)``,
and it holds for stratified samples too: with cell fractions ``f_i`` of mean ``f``,
``P(no hit) = prod(1 - f_i) <= (1 - f)^n`` (the arithmetic-geometric mean inequality). So a
receiver is called umbra or lit only after about ``ln(1/(1 - c)) / tolerance`` samples (459
at 99 % and 0.01): 16 agreeing samples are no evidence at 0.01.
"""
from __future__ import annotations

import functools
import math

import numpy as np


# a pure function of (p, dof) that every area light's reference asks again per stage (90 times in
# a small run, 60 ms each): computed once per pair, the same float64 answer
@functools.lru_cache(maxsize=64)
def t_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile (p > 0.5) of Student's t with ``dof`` degrees of freedom (float64:
    Simpson's rule on the density, then bisection; no scipy needed; remembered per (p, dof))."""
    if not 0.5 < p < 1.0 or dof < 1:
        raise ValueError(f"t_quantile needs 0.5 < p < 1 and dof >= 1, got p={p}, dof={dof}")
    log_c = math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2) - 0.5 * math.log(dof * math.pi)

    def cdf(x: float) -> float:
        # substitution t = tan(theta) keeps the heavy tail of dof = 1 well sampled
        th = np.linspace(0.0, math.atan(x), 4001)
        t = np.tan(th)
        f = np.exp(log_c - (dof + 1) / 2 * np.log1p(t * t / dof)) / np.cos(th) ** 2
        h = th[1] - th[0]
        return 0.5 + h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())

    lo, hi = 0.0, 1.0
    while cdf(hi) < p:
        hi *= 2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def zero_count_bound(n, confidence: float):
    """The one-sided upper bound on a fraction when none of ``n`` samples hit:
    ``1 - (1 - confidence)^(1/n)`` (numpy)."""
    n = np.maximum(np.asarray(n, np.float64), 1.0)
    return -np.expm1(np.log1p(-confidence) / n)


def samples_to_certify(tolerance: float, confidence: float) -> int:
    """The fewest samples whose zero-count bound is within ``tolerance``: what a receiver that
    sees all or none of the light needs before it may stop (inf where tolerance is 0)."""
    if tolerance <= 0:
        return math.inf
    if tolerance >= 1:
        return 1
    return math.ceil(math.log1p(-confidence) / math.log1p(-tolerance))


def replicate_interval(rep_hits, per_replicate, confidence: float) -> tuple:
    """(estimate, low, high) per receiver from its replicates' hit counts ``rep_hits`` (m, B),
    each of ``per_replicate`` samples: the mean, and Student's t interval of the replicates'
    means (at least one sample's width, 1/n, wide), or the zero-count bound where every sample
    agrees (numpy, float64)."""
    rep_hits = np.asarray(rep_hits, np.float64)
    m, b = rep_hits.shape
    n = float(per_replicate * b)
    k = rep_hits.sum(1)
    v = k / max(n, 1.0)
    if b >= 2:
        s = (rep_hits / max(per_replicate, 1)).std(axis=1, ddof=1)
        half = t_quantile(0.5 + confidence / 2, b - 1) * s / math.sqrt(b)
    else:
        half = np.full(m, np.inf)
    half = np.maximum(half, 1.0 / max(n, 1.0))
    lo, hi = np.clip(v - half, 0.0, 1.0), np.clip(v + half, 0.0, 1.0)
    edge = zero_count_bound(n, confidence)
    lo = np.where(k == 0, 0.0, np.where(k == n, 1.0 - edge, lo))
    hi = np.where(k == 0, edge, np.where(k == n, 1.0, hi))
    return v, lo, hi
