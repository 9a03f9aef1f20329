"""The paired bootstrap that tells two error rates apart, or calls them a tie.

Two instances measured on the same situations (cases, or scene and light pairs) are compared
situation by situation: the data cannot tell them apart where the bootstrap interval (RESAMPLES
resamples of the paired differences, with replacement, numpy's PCG64 seeded with SEED) of the mean
difference, at CONFIDENCE, contains 0. The benchmark's ranking (dsm.benchmark.ranking) and a run's
cost-accuracy answer (dsm.report.frontier) use this one rule, so their ties mean the same.
"""
from __future__ import annotations

import numpy as np

SEED = 0
RESAMPLES = 2000
CONFIDENCE = 0.95


def interval(differences) -> tuple:
    """(low, high): the bootstrap interval at CONFIDENCE of the mean of the paired ``differences`` (float64)."""
    d = np.asarray(differences, np.float64)
    means = d[np.random.default_rng(SEED).integers(0, d.size, (RESAMPLES, d.size))].mean(axis=1)
    low, high = np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return float(low), float(high)


def apart(differences) -> bool:
    """Whether the paired ``differences`` tell the two sides apart (their interval excludes 0); none: no."""
    if len(differences) == 0:
        return False
    low, high = interval(differences)
    return low > 0 or high < 0
