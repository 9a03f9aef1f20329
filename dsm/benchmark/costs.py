"""The leaderboard at equal cost: each contender's costs in counts, its memory class, the frontier.

From results version 4 on a depth, pre-filtered or virtual record carries its case's costs
(:mod:`dsm.case.cost`: ``map_bytes``, ``page_table_bytes``, ``map_rays``, ``taps``). A contender's
cost is the mean over its records at the origin; its *memory class* is the factor of 2 of bytes it
falls in (``[2^k, 2^(k+1))``), and contenders are ranked inside each class by the ranking's rule
(:mod:`dsm.benchmark.ranking`), never across a 30x gap of memory. *On the frontier*: no other
contender has a mean error rate, mean bytes and mean rays each at most its own, one of them lower
(the per-situation frontier is frontier.csv's, :mod:`dsm.report.frontier`). A document of an older
version has no costs: the page says so and keeps the plain ranking. A hybrid contender's rays (dsm-bench-6 on)
are its map's and the rays its rule traced (``map_rays + hybrid_rays``), as a run's frontier counts them.
"""
from __future__ import annotations

import math

import numpy as np

from ..report import frontier
from . import ranking

COST_KEYS = ("map_bytes", "page_table_bytes", "map_rays", "taps")


def has_costs(doc: dict) -> bool:
    """Whether every contender record of ``doc`` carries the cost counts (results version 4 on)."""
    recs = [r for r in doc["cases"] if r["contender"] != "oracle"]
    return bool(recs) and all(all(k in r for k in COST_KEYS) for r in recs)


def family_of(contender: str) -> str:
    """The family a tie's words group a contender by: its first word (``vsm box:5`` -> ``vsm``)."""
    return contender.split()[0]


def points(doc: dict) -> list:
    """frontier Points of the records at the origin: a situation is (scene at its unit, light)."""
    out = []
    for r in doc["cases"]:
        if r["contender"] == "oracle" or not ranking.at_origin(r):
            continue
        n = r["n_receivers"]
        out.append(frontier.Point(f"{r['scene']} {r['unit']}", r["light"], r["light"], r["contender"],
                                  family_of(r["contender"]), (r["n_acne"] + r["n_peterpan"]) / n if n else math.nan,
                                  int(r["map_bytes"]) + int(r["page_table_bytes"]), rays_of(r),
                                  float(r["taps"]), float(r["build_ms"]), float(r["lookup_ms"])))
    return out


def rays_of(rec: dict) -> int:
    """A record's rays: its map's, and a hybrid contender's traced rays with them."""
    return int(rec["map_rays"]) + int(rec.get("hybrid_rays", 0))


def contender_costs(doc: dict) -> dict:
    """Contender -> {bytes, rays, taps}: the means over its records at the origin."""
    acc = {}
    for p in points(doc):
        acc.setdefault(p.instance, []).append((p.bytes, p.rays, p.taps))
    return {c: dict(zip(("bytes", "rays", "taps"), np.mean(np.array(v, np.float64), axis=0).tolist()))
            for c, v in acc.items()}


def memory_class(n_bytes: float) -> int:
    """The factor-of-2 class of ``n_bytes``: k with 2^k <= n_bytes < 2^(k+1) (0 for under 2 bytes)."""
    return int(math.floor(math.log2(n_bytes))) if n_bytes >= 1 else 0


def class_label(k: int) -> str:
    """A memory class in words: ``1 MiB to 2 MiB``."""
    return f"{frontier.size(2 ** k)} to {frontier.size(2 ** (k + 1))}"


def on_frontier(ranked: list, costs: dict) -> set:
    """The contenders no other beats on mean error without costing more in mean bytes and rays."""
    rows = [(r["contender"], r["error"], costs[r["contender"]]["bytes"], costs[r["contender"]]["rays"])
            for r in ranked if r["contender"] in costs and r["error"] == r["error"]]
    out = set()
    for name, e, b, n in rows:
        if not any(e2 <= e and b2 <= b and n2 <= n and (e2, b2, n2) != (e, b, n) for _, e2, b2, n2 in rows):
            out.add(name)
    return out


def classes(doc: dict, ranked: list) -> list:
    """[(class k, its rows ranked inside it by the ranking's rule)], cheapest class first; each row the
    ranking's with ``bytes``, ``rays``, ``taps`` and ``on_frontier``."""
    costs = contender_costs(doc)
    front = on_frontier(ranked, costs)
    by_name = ranking.contender_rows(doc)
    groups = {}
    for r in ranked:
        if r["contender"] in costs:
            c = costs[r["contender"]]
            groups.setdefault(memory_class(c["bytes"]), []).append({**r, **c, "on_frontier": r["contender"] in front})
    return [(k, ranking.ranked_within(groups[k], by_name)) for k in sorted(groups)]


def answer_lines(doc: dict) -> list:
    """What accuracy costs, in words (dsm.report.frontier's, over the records at the origin); a document
    without costs says so."""
    if not has_costs(doc):
        return [f"results_version {doc.get('results_version', 1)} records no costs: the ranking below is by error "
                "alone (run this dsm's benchmark for memory classes and the frontier)"]
    found = frontier.answers(points(doc))
    return frontier.answer_lines(found) + frontier.time_lines(found)


def write_frontier(doc: dict, out) -> bool:
    """frontier.csv of the records at the origin beside results.json (:mod:`dsm.report.frontier`'s
    columns); False (nothing written, an old one removed) for a document without costs."""
    from pathlib import Path
    path = Path(out) / "frontier.csv"
    if not has_costs(doc):
        path.unlink(missing_ok=True)
        return False
    frontier.write_csv(path, points(doc))
    return True
