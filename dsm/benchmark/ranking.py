"""The leaderboard's numbers: the ranking with its tie rule, scale robustness, the oracle floor.

A contender's score is its error rate (acne and peter-panning over receivers) averaged over every
case it ran (scene x unit x light). Two contenders run on the same cases, so they are compared case
by case: a rank is shared where the data cannot tell them apart, that is where the bootstrap
interval (RESAMPLES resamples of the cases both ran, with replacement, numpy's PCG64 seeded with
SEED) of the mean per-case difference of their error rates, at CONFIDENCE, contains 0. Contenders
are taken best score first; each is compared with the first of the current rank, and joins it or
opens the next (competition ranking: 1, 1, 3); a rank's rows are listed by score, then by name. Scale spread: for each (scene, light), the largest
minus the smallest error rate over the units, averaged; the smallest spread is the most
scale-robust. The score and the spread read the cases at the origin only; from dsm-bench-2 on the
far-from-origin cases (every scene at the suite's ``far_unit``, moved by each offset) give each
contender its error rate per offset and its far change: the mean over (scene, light) of its error
at the farthest offset less its error at the origin (same unit). From dsm-bench-3 on a pre-filtered
contender also has its pooled leak rate: its n_leak summed over the cases at the origin over their
summed n_gt_shadowed (a depth contender: None), and a depth contender its flicker: the mean flicker_rate
of its records in the document's ``flicker`` list (None without any; no oracle floor). From dsm-bench-6 on a
hybrid contender has its ray fraction: its rays summed over the cases at the origin over their summed receivers
(:func:`pooled_rays`; a map alone: None).
"""
from __future__ import annotations

import math
from collections import defaultdict

from ..truth import paired
from .suite import ORIGIN

SEED, RESAMPLES, CONFIDENCE = paired.SEED, paired.RESAMPLES, paired.CONFIDENCE
RULE = {"test": "paired bootstrap of the mean per-case error-rate difference over the cases both ran at the origin",
        "resamples": RESAMPLES, "seed": SEED, "confidence": CONFIDENCE}
RULE_TEXT = (f"Two contenders share a rank where the data cannot tell them apart: the {CONFIDENCE:.0%} bootstrap "
             f"interval ({RESAMPLES} resamples of the cases both ran at the origin, seed {SEED}) of the mean "
             "per-case difference of their error rates contains 0; each contender is compared with the first of "
             "its rank, and a rank's rows are listed by error rate.")


def offset_of(rec: dict) -> str:
    """A record's offset label (a dsm-bench-1 record, which has none, sits at the origin)."""
    return rec.get("offset", ORIGIN)


def at_origin(rec: dict) -> bool:
    """Whether a record's case sits at the origin."""
    return offset_of(rec) == ORIGIN


def offsets(doc: dict) -> list:
    """The offset labels of a result's cases, the origin first, in the order the cases ran."""
    out = [ORIGIN]
    for r in doc["cases"]:
        if offset_of(r) not in out:
            out.append(offset_of(r))
    return out


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


def far_change(rows: list, far_unit: str, offset: str) -> float:
    """The mean over (scene, light) of the error rate at ``offset`` less the one at the origin, both at ``far_unit``."""
    by = defaultdict(dict)
    for r in rows:
        if r["unit"] == far_unit:
            by[(r["scene"], r["light"])][offset_of(r)] = r["error_rate"]
    return mean(d[offset] - d[ORIGIN] for d in by.values() if offset in d and ORIGIN in d)


def pooled_leak(rows: list):
    """Sum of n_leak over sum of n_gt_shadowed of ``rows`` (None unless every row has a leak count; NaN
    when none is shadowed)."""
    if not rows or not all("n_leak" in r for r in rows):
        return None
    shadowed = sum(r["n_gt_shadowed"] for r in rows)
    return sum(r["n_leak"] for r in rows) / shadowed if shadowed else float("nan")


def pooled_rays(rows: list):
    """Sum of hybrid_rays over sum of n_receivers of ``rows`` (None unless every row traced rays: a map alone;
    NaN when no row has a receiver)."""
    if not rows or not all("hybrid_rays" in r for r in rows):
        return None
    receivers = sum(r["n_receivers"] for r in rows)
    return sum(r["hybrid_rays"] for r in rows) / receivers if receivers else float("nan")


def scores(name: str, rows: list, far_unit, far: list) -> dict:
    """One contender's leaderboard numbers from its records: origin means, FLIP, far columns."""
    here = [r for r in rows if at_origin(r)]
    out = {"contender": name, "error": mean(r["error_rate"] for r in here),
           "acne": mean(r["acne_rate"] for r in here), "peterpan": mean(r["peterpan_rate"] for r in here),
           "spread": scale_spread(here), "build_ms": mean(r["build_ms"] for r in here),
           "lookup_ms": mean(r["lookup_ms"] for r in here),
           "flip": mean(r["flip"] for r in here) if all("flip" in r for r in here) else None,
           "leak": pooled_leak(here), "ray_fraction": pooled_rays(here)}
    out["far"] = {o: mean(r["error_rate"] for r in rows if offset_of(r) == o and r["unit"] == far_unit)
                  for o in far}
    out["far_change"] = far_change(rows, far_unit, far[-1]) if len(far) > 1 else None
    return out


def flicker_by(doc: dict) -> dict:
    """Contender -> the mean flicker_rate of its flicker records (over scenes and lights)."""
    acc = defaultdict(list)
    for r in doc.get("flicker", []):
        acc[r["contender"]].append(r["flicker_rate"])
    return {c: mean(v) for c, v in acc.items()}


def paired_interval(a_rows: list, b_rows: list):
    """(low, high): the bootstrap interval at CONFIDENCE of the mean over the cases both ran at the
    origin (with a defined error rate) of b's error rate less a's; None without a shared case."""
    key = lambda r: (r["scene"], r["unit"], r["light"])
    a = {key(r): r["error_rate"] for r in a_rows if at_origin(r) and r["error_rate"] == r["error_rate"]}
    b = {key(r): r["error_rate"] for r in b_rows if at_origin(r) and r["error_rate"] == r["error_rate"]}
    shared = sorted(set(a) & set(b))
    if not shared:
        return None
    return paired.interval([b[k] - a[k] for k in shared])


def apart(a_rows: list, b_rows: list) -> bool:
    """Whether the cases tell b from a (the paired interval excludes 0); without a shared case, no."""
    interval = paired_interval(a_rows, b_rows)
    return interval is not None and (interval[0] > 0 or interval[1] < 0)


def ranking(doc: dict) -> list:
    """The leaderboard rows, best first: rank (RULE_TEXT), contender, score, acne, peter-pan, scale
    spread, FLIP, error per offset (``far``: offset -> error at the far unit) and the far change."""
    far = offsets(doc) if doc.get("far_unit") else []
    flick = flicker_by(doc)
    by_name = contender_rows(doc)
    scored = [{**scores(name, rows, doc.get("far_unit"), far), "flicker": flick.get(name)}
              for name, rows in by_name.items()]
    return ranked_within(scored, by_name)


def ranked_within(scored: list, by_name: dict) -> list:
    """``scored`` rows (each with contender and error) ranked among themselves by RULE_TEXT's rule,
    best first, each with its ``rank``; ``by_name``: contender -> its records (contender_rows)."""
    scored = sorted(scored, key=lambda s: (s["error"], s["contender"]))
    out, lead = [], None
    for i, s in enumerate(scored):
        if lead is None or apart(by_name[lead["contender"]], by_name[s["contender"]]):
            lead = {**s, "rank": i + 1}
        out.append({**s, "rank": lead["rank"]})
    out.sort(key=lambda s: (s["rank"], s["error"], s["contender"]))
    return out


def most_scale_robust(ranked: list, among=None):
    """The row with the smallest scale spread (among contender names ``among`` if given; ties by score);
    None when no row has a spread (none of them, or a run at one unit)."""
    pool = [r for r in ranked if (among is None or r["contender"] in among) and not math.isnan(r["spread"])]
    return min(pool, key=lambda r: (r["spread"], r["error"], r["contender"])) if pool else None


def oracle_floor(doc: dict) -> dict:
    """The oracles' objectives averaged over the cases at the origin: world, texel and per-texel."""
    rows = [r for r in doc["cases"] if r["contender"] == "oracle" and at_origin(r)]
    return {k: mean(r[k] for r in rows) for k in ("world_objective", "texel_objective", "per_texel_objective")}


def error_by(doc: dict, key, keep=at_origin) -> dict:
    """Contender -> {key(record): mean error rate} over the records ``keep`` passes (default: at the
    origin), with the oracle's per-texel floor as ``oracle``."""
    acc = defaultdict(lambda: defaultdict(list))
    for r in doc["cases"]:
        if not keep(r):
            continue
        value = r["per_texel_objective"] if r["contender"] == "oracle" else r["error_rate"]
        acc[r["contender"]][key(r)].append(value)
    return {c: {k: mean(v) for k, v in d.items()} for c, d in acc.items()}
