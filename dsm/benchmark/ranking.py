"""The leaderboard's numbers: the ranking with its tie rule, scale robustness, the oracle floor.

A contender's score is its error rate (acne and peter-panning over receivers) averaged over every
case it ran (scene x unit x light). Two contenders whose scores differ by less than 0.001 (0.1 %
of receivers, the machines' rounding, :mod:`dsm.benchmark.compare`) tie: they share a rank
(competition ranking: 1, 1, 3), listed by name. Scale spread: for each (scene, light), the largest
minus the smallest error rate over the units, averaged; the smallest spread is the most
scale-robust.
"""
from __future__ import annotations

import math
from collections import defaultdict

TIE_RATE = 0.001


def contender_rows(doc: dict) -> dict:
    """Contender -> its case records (the oracle's left out)."""
    out = defaultdict(list)
    for r in doc["cases"]:
        if r["contender"] != "oracle":
            out[r["contender"]].append(r)
    return dict(out)


def mean(values) -> float:
    """The arithmetic mean of ``values`` (NaN when empty)."""
    values = list(values)
    return sum(values) / len(values) if values else float("nan")


def scale_spread(rows: list) -> float:
    """The mean over (scene, light) of the error rate's range across units."""
    by = defaultdict(list)
    for r in rows:
        by[(r["scene"], r["light"])].append(r["error_rate"])
    return mean(max(v) - min(v) for v in by.values() if len(v) > 1)


def ranking(doc: dict) -> list:
    """The leaderboard rows, best first: rank, contender, score, acne, peter-pan, scale spread."""
    scored = []
    for name, rows in contender_rows(doc).items():
        scored.append({"contender": name, "error": mean(r["error_rate"] for r in rows),
                       "acne": mean(r["acne_rate"] for r in rows), "peterpan": mean(r["peterpan_rate"] for r in rows),
                       "spread": scale_spread(rows), "build_ms": mean(r["build_ms"] for r in rows),
                       "lookup_ms": mean(r["lookup_ms"] for r in rows)})
    scored.sort(key=lambda s: (s["error"], s["contender"]))
    out, lead = [], None
    for i, s in enumerate(scored):
        if lead is None or s["error"] - lead["error"] >= TIE_RATE:
            lead = {**s, "rank": i + 1}
        out.append({**s, "rank": lead["rank"]})
    out.sort(key=lambda s: (s["rank"], s["contender"]))
    return out


def most_scale_robust(ranked: list, among=None):
    """The row with the smallest scale spread (among contender names ``among`` if given; ties by score);
    None when no row has a spread (none of them, or a run at one unit)."""
    pool = [r for r in ranked if (among is None or r["contender"] in among) and not math.isnan(r["spread"])]
    return min(pool, key=lambda r: (r["spread"], r["error"], r["contender"])) if pool else None


def oracle_floor(doc: dict) -> dict:
    """The oracles' objectives averaged over the cases: world, texel and per-texel."""
    rows = [r for r in doc["cases"] if r["contender"] == "oracle"]
    return {k: mean(r[k] for r in rows) for k in ("world_objective", "texel_objective", "per_texel_objective")}


def error_by(doc: dict, key) -> dict:
    """Contender -> {key(record): mean error rate}, with the oracle's per-texel floor as ``oracle``."""
    acc = defaultdict(lambda: defaultdict(list))
    for r in doc["cases"]:
        value = r["per_texel_objective"] if r["contender"] == "oracle" else r["error_rate"]
        acc[r["contender"]][key(r)].append(value)
    return {c: {k: mean(v) for k, v in d.items()} for c, d in acc.items()}
