"""What accuracy costs: the cost-accuracy frontier of a run, and its answer in words.

A *point* is one instance in one situation: its error rate and its costs in counts
(:mod:`dsm.case.cost`: ``bytes`` = the bytes its lookup reads plus a virtual map's page table,
``rays`` = the rays its map took, ``taps`` per lookup), with the measured build and lookup times
beside. The situation is the scene and light (in the benchmark, the scene at its unit and the
light); the map's resolution, view, filter, stored format, culling, cascade layout and kind are
choices on the cost side, part of the instance.

- **On the frontier**: no other point of the same situation has an error rate, bytes and rays each
  at most its own, one of them lower. Points equal on all three are both on it (a tie). Time never
  decides (a clock reading has noise; counts do not); a point with an undefined error rate (no
  receivers) is on no frontier and says so (an empty ``on_frontier``).
- **The answer**, per light type, over its situations: among the instances run in every one of
  them, the lowest mean error rate; the instances the paired bootstrap (:mod:`dsm.truth.paired`,
  the benchmark's rule) cannot tell from it; the cheapest of those (bytes, then rays, then taps,
  then label), named with its error, bytes, rays and times; the families of the others that tie;
  what a lower error costs: the lowest error's and the cheapest at half its error or less, with
  their bytes as a multiple; and what half its memory or less gives: the lowest error among the
  instances that cheap.

:func:`answer_lines` gives the words that the report's first screen, ``dsm run``'s last lines and
the leaderboard's headline all print.
"""
from __future__ import annotations

import math
from collections import Counter, defaultdict
from dataclasses import dataclass

import numpy as np

from ..truth import paired
from ..truth.metrics import defined
from . import io as report_io

CHOICES = ("view", "filter", "format", "culling", "cascade_layout", "map_kind", "motion")   # named where they vary
CSV_COLUMNS = ("scene", "light", "instance", "error_rate", "bytes", "rays", "taps", "build_ms", "lookup_ms",
               "on_frontier")
TIME_COLUMNS = ("build_ms", "lookup_ms")
FLOOR_RULES = ("oracle",)       # a hybrid rule that reads V* is the floor (hybrid.md), not an instance to use


@dataclass(frozen=True)
class Point:
    """One instance in one situation: its error rate, its costs in counts and its measured times."""
    scene: str
    light: str          # the situation's light (its label)
    light_type: str     # directional, spot, point, area
    instance: str
    family: str         # the scheme, preset or kind: what a tie's words group by
    error: float
    bytes: int
    rays: int
    taps: float
    build_ms: float
    lookup_ms: float


def has_costs(rows) -> bool:
    """Whether metrics rows carry the cost columns (a run from before them does not)."""
    return bool(rows) and all("map_bytes" in r and r["map_bytes"] not in ("", None) for r in rows)


def instance_label(row: dict, varied=()) -> str:
    """A row's instance: its preset or scheme and parameters, its resolution, and the ``varied`` choices."""
    name = row["preset"] or " ".join(x for x in (row["scheme"], row["params"]) if x)
    extra = [str(row.get(k) or "") for k in varied if not (k == "culling" and row.get(k) == "none")]
    return " ".join([name, f"at {row['resolution']}", *[x for x in extra if x]])


def varied_choices(rows) -> tuple:
    """The choices (CHOICES) that take more than one value over ``rows``."""
    return tuple(k for k in CHOICES if len({str(r.get(k) or "") for r in rows}) > 1)


def light_type(row: dict) -> str:
    """A row's light type from its label (``0:directional`` -> ``directional``)."""
    return row["light"].split(":", 1)[-1]


def error_rate(row: dict) -> float:
    """(n_acne + n_peterpan) / n_receivers from the counts (exact whether the row was read from
    metrics.csv or not); undefined without receivers."""
    n = row["n_receivers"]
    return (row["n_acne"] + row["n_peterpan"]) / n if n else math.nan


def _six(x) -> float:
    """A float as metrics.csv writes it (6 significant digits), so rows in memory and read back agree."""
    x = float(x)
    return float(f"{x:.6g}") if defined(x) else x


def points_from_rows(rows) -> list:
    """The points of a run's metrics rows (none for rows without the cost columns); an instance's
    label names the choices that vary among its light type's rows. A hybrid row (dsm.hybrid) gives
    two points: the map alone (once per map case) and the map with its rule's rays, whose error is the
    error left after them and whose rays add the rays traced."""
    if not has_costs(rows):
        return []
    varied = {t: varied_choices([r for r in rows if light_type(r) == t]) for t in {light_type(r) for r in rows}}
    out, seen = [], set()
    for r in rows:
        base = _point(r, instance_label(r, varied[light_type(r)]))
        if not r.get("hybrid_rule"):
            out.append(base)
            continue
        if (base.scene, base.light, base.instance) not in seen:      # the map alone, the budget's 0
            seen.add((base.scene, base.light, base.instance))
            out.append(base)
        if r["hybrid_rule"] not in FLOOR_RULES:
            out.append(_hybrid_point(r, base))
    return out


def _point(r: dict, instance: str) -> Point:
    """A metrics row's point (the map alone)."""
    return Point(r["scene"], r["light"], light_type(r), instance, r["preset"] or r["scheme"], error_rate(r),
                 int(r["map_bytes"]) + int(r["page_table_bytes"]), int(r["map_rays"]), _six(r["taps"]),
                 _six(r["build_ms"]), _six(r["lookup_ms"]))


def _hybrid_point(r: dict, base: Point) -> Point:
    """A hybrid row's point: the error left after its rule's rays, the rays traced added to the map's."""
    n = r["n_receivers"]
    words = " ".join(x for x in (r["hybrid_rule"], r.get("hybrid_params") or "") if x)
    origin = r.get("hybrid_origin") or ""
    instance = f"{base.instance} + rays: {words}" + (f" from {origin}" if origin and origin != "spawn" else "")
    left = (r["hybrid_n_acne"] + r["hybrid_n_peterpan"]) / n if n else math.nan
    return Point(base.scene, base.light, base.light_type, instance, base.family, left, base.bytes,
                 base.rays + int(r["hybrid_rays"]), base.taps, base.build_ms,
                 _six(base.lookup_ms + float(r["hybrid_ms"])))


def on_frontier(points: list) -> list:
    """Per point: True on its situation's frontier, False dominated, None with an undefined error rate."""
    out = [None] * len(points)
    groups = defaultdict(list)
    for i, p in enumerate(points):
        if defined(p.error):
            groups[(p.scene, p.light)].append(i)
    for idx in groups.values():
        cost = np.array([[points[i].error, points[i].bytes, points[i].rays] for i in idx], np.float64)
        for k, i in enumerate(idx):
            at_most = (cost <= cost[k]).all(axis=1)
            lower = (cost < cost[k]).any(axis=1)
            out[i] = not bool((at_most & lower).any())
    return out


def csv_rows(points: list) -> list:
    """frontier.csv's rows: a point each, in the run's order, with ``on_frontier`` 1, 0 or empty."""
    marks = on_frontier(points)
    return [{"scene": p.scene, "light": p.light, "instance": p.instance, "error_rate": p.error, "bytes": p.bytes,
             "rays": p.rays, "taps": p.taps, "build_ms": p.build_ms, "lookup_ms": p.lookup_ms,
             "on_frontier": "" if m is None else int(m)} for p, m in zip(points, marks)]


def write_csv(path, points: list):
    """Write frontier.csv (atomically) from ``points``."""
    report_io.write_csv(path, list(CSV_COLUMNS), csv_rows(points))


@dataclass(frozen=True)
class Choice:
    """One instance over a light type's situations: its means."""
    instance: str
    family: str
    error: float
    bytes: float
    rays: float
    taps: float
    build_ms: float
    lookup_ms: float
    errors: tuple       # per situation, in the light type's order

    @property
    def cost_key(self) -> tuple:
        """Cheapest first: bytes, then rays, then taps, then the label."""
        return self.bytes, self.rays, self.taps, self.instance


def choices(points: list) -> tuple:
    """(situations, [Choice]) of one light type: the instances with a defined error in every situation."""
    situations = sorted({(p.scene, p.light) for p in points})
    by = defaultdict(dict)
    for p in points:
        if defined(p.error):
            by[(p.instance, p.family)][(p.scene, p.light)] = p
    out = []
    for (inst, fam), d in by.items():
        if len(d) < len(situations):
            continue
        ps = [d[s] for s in situations]
        m = lambda f: float(np.mean([f(p) for p in ps]))
        out.append(Choice(inst, fam, m(lambda p: p.error), m(lambda p: p.bytes), m(lambda p: p.rays),
                          m(lambda p: p.taps), m(lambda p: p.build_ms), m(lambda p: p.lookup_ms),
                          tuple(p.error for p in ps)))
    return situations, out


def answer(points: list) -> dict | None:
    """One light type's answer (see the module): best, chosen, tied, half; None without an instance run everywhere."""
    situations, cands = choices(points)
    if not cands:
        return None
    best = min(cands, key=lambda c: (c.error, *c.cost_key))
    tied = [c for c in cands if not paired.apart(np.subtract(c.errors, best.errors))]
    chosen = min(tied, key=lambda c: c.cost_key)
    better = [c for c in cands if c.error <= chosen.error / 2] if chosen.error > 0 else []
    half = min(better, key=lambda c: c.cost_key) if better else None
    thrifty = [c for c in cands if c.bytes <= chosen.bytes / 2]
    saving = min(thrifty, key=lambda c: (c.error, *c.cost_key)) if thrifty else None
    return {"light_type": points[0].light_type, "situations": len(situations), "instances": len(cands),
            "best": best, "chosen": chosen, "tied": sorted(tied, key=lambda c: c.cost_key), "half": half,
            "saving": saving}


def answers(points: list) -> list:
    """Per light type (in the order the run met them), its answer (:func:`answer`), those with one."""
    order = list(dict.fromkeys(p.light_type for p in points))
    out = [answer([p for p in points if p.light_type == t]) for t in order]
    return [a for a in out if a is not None]


def size(n: float) -> str:
    """Bytes in binary units, 3 significant digits (``1 MiB``, ``384 KiB``)."""
    for unit, k in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << k:
            return f"{n / (1 << k):.3g} {unit}"
    return f"{n:.0f} B"


def _rate(x: float) -> str:
    return "0" if x == 0 else f"{x:.2g}"


def _cost(c: Choice) -> str:
    return f"{size(c.bytes)}, {c.rays:,.0f} rays, {c.taps:.3g} tap{'' if c.taps == 1 else 's'}"


def family_counts(families) -> list:
    """[(family, how many)] of ``families`` (one name per instance), most first, then by name."""
    return sorted(Counter(families).items(), key=lambda t: (-t[1], t[0]))


def families(tied: list, chosen: Choice) -> str:
    """The other tied instances as their families and counts (``adaptive 5, constant 3``), most first."""
    return ", ".join(f"{f} {n}" for f, n in family_counts(c.family for c in tied if c is not chosen))


def answer_words(a: dict) -> tuple:
    """(what to use, why: the ties, what a lower error costs) of one light type's answer, in words (counts only)."""
    c, n_tied = a["chosen"], len(a["tied"]) - 1
    n = a["situations"]
    head = f"{a['light_type']} ({n} situation{'' if n == 1 else 's'}): {c.instance}: error {_rate(c.error)}, {_cost(c)}"
    if n_tied == 0:
        why = "the lowest error, told apart from every other instance"
    else:
        what = "the lowest error" if c is a["best"] else "the cheapest the data cannot tell from the lowest"
        why = f"{what}; {n_tied} more tie: {families(a['tied'], c)}"
    return head, why, costs_more(c, a["best"], a["half"]) + saves(c, a["saving"])


def answer_lines(found: list) -> list:
    """The answer in words, two lines per light type: what to use (counts only, so identical runs say
    the same) and what a lower error costs; :func:`time_lines` gives the measured times beside."""
    out = []
    for a in found:
        head, why, more = answer_words(a)
        out += [f"{head} ({why})", "  " + more]
    return out


def _pay(c: Choice, other: Choice) -> str:
    ratio = other.bytes / c.bytes if c.bytes else math.inf
    memory = "the same memory" if ratio == 1 else f"{ratio:.2g}x the memory"
    return f"{memory}: {other.instance} ({_cost(other)})"


def costs_more(c: Choice, best: Choice, half: Choice | None) -> str:
    """What a lower error than the chosen instance's costs: the lowest error's, and half its error's."""
    if half is not None and half is best:
        return f"the lowest, {_rate(best.error)}, halves it and costs {_pay(c, best)}"
    lowest = "" if best is c else f"the lowest, {_rate(best.error)}, costs {_pay(c, best)}; "
    if c.error == 0:
        return lowest + "no error left to halve"
    if half is None:
        return lowest + f"no instance run halves its error (at most {_rate(c.error / 2)})"
    return lowest + f"for {_rate(half.error)} you pay {_pay(c, half)}"


def saves(c: Choice, saving: Choice | None) -> str:
    """What half the memory or less gives: the lowest error among the instances that cheap ('' where none ran)."""
    if saving is None:
        return ""
    ratio = c.bytes / saving.bytes if saving.bytes else math.inf
    return (f"; at {ratio:.2g}x less memory the lowest error is {_rate(saving.error)}: {saving.instance} "
            f"({_cost(saving)})")


def time_lines(found: list) -> list:
    """The measured times of each light type's named instances (means of the per-case medians, ms)."""
    out = []
    for a in found:
        named = [x for x in (a["chosen"], a["best"], a["half"], a["saving"]) if x is not None]
        out.append(f"{a['light_type']}: " + "; ".join(
            f"{x.instance}: build {x.build_ms:.3g} ms, lookup {x.lookup_ms:.3g} ms"
            for x in dict.fromkeys(named)))
    return out


DEFINITION = ("Per light type, over its situations (scene and light): the cheapest instance (bytes its lookup "
              "reads, then rays its map took, then taps per lookup) among those whose error rate the paired "
              "bootstrap (95 %, 2000 resamples, seed 0) cannot tell from the lowest mean error rate; then what a "
              "lower error costs and what half the memory gives. Resolution, view, filter, format and culling are "
              "choices on the cost side. "
              "Times are measured and shown, never deciding. frontier.csv holds every instance's error, bytes, "
              "rays, taps and times, and whether it is on its situation's frontier (no other instance has at most "
              "its error, bytes and rays, one of them lower).")


def summary_md(points: list) -> list:
    """table.md's first section: the answer in words, and how many points are on the frontier."""
    if not points:
        return ["## What accuracy costs", "", "This run's rows carry no costs (a run from before dsm 0.6): "
                "no frontier.", ""]
    marks = on_frontier(points)
    n_on = sum(1 for m in marks if m)
    found = answers(points)
    lines = [f"- {x.strip()}" if not x.startswith(" ") else f"  - {x.strip()}" for x in answer_lines(found)]
    return ["## What accuracy costs", "", *lines, "", "Measured times:", "", *[f"- {x}" for x in time_lines(found)], "",
            DEFINITION + f" {n_on} of {len(points)} points are on their frontier.", ""]
