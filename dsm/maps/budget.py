"""Equal budgets: the cascade resolution whose texels (or rays) match another map's as closely as
whole texels allow (docs/vsm_vs_cascades.md)."""
from __future__ import annotations

import math


def cascade_resolution(target: float, count: int) -> int:
    """The resolution R >= 1 whose ``count`` cascades of R^2 hold the nearest number of texels to
    ``target`` (``count R^2`` against ``target``); on a tie the smaller R (never over budget)."""
    if not target > 0 or count < 1:
        raise ValueError(f"a budget needs target > 0 texels and count >= 1 cascades, got {target!r}, {count!r}")
    r0 = max(1, math.isqrt(int(target // count)))
    best = min((abs(count * r * r - target), r) for r in (r0 - 1, r0, r0 + 1, r0 + 2) if r >= 1)
    return best[1]


def budget_gap(resolution: int, count: int, target: float) -> float:
    """Relative gap ``(count R^2 - target) / target`` of a resolution against its budget."""
    return (count * resolution * resolution - target) / target
