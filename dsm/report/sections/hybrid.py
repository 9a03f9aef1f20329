"""A run with ``[hybrid]``: hybrid.md (the rays each rule traced and the error left, pooled; the
rays each rule needs for zero error), the budget curves (plots/hybrid_*.png: error against rays
per receiver, the map alone at 0, the oracle's curve the floor) and their section of report.html."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import figures, glyph_cache, io as report, summary
from . import md
from ..templates import Cell, Row, Table
from ...truth import metrics

INTRO = ("Each hybrid case is a depth case whose receivers a rule sends to rays (dsm.hybrid, docs/hybrid.md): "
         "the map answers the rest. Rays per receiver: rays traced / receivers (pooled: summed over cases); "
         "error before: the map alone (error_rate); after: with the rays (hybrid_error_rate); ray wrong: rays "
         "whose answer is not V* (a shortened ray or an origin rule's own error). Undefined: -.")


def hybrid_rows(rows: list) -> list:
    """The rows of hybrid cases (their rule given)."""
    return [r for r in rows if r.get("hybrid_rule") not in (None, "")]


def _ratio(a, b) -> float:
    return a / b if b else metrics.UNDEFINED


def _rule_label(r) -> str:
    """A hybrid instance in words: rule, parameters, origin."""
    return " ".join(x for x in (r["hybrid_rule"], r["hybrid_params"], f"origin={r['hybrid_origin']}") if x)


def pooled(rows: list) -> list:
    """Per (scheme instance, hybrid instance): [labels..., cases, rays per receiver, error before, after, ray wrong]."""
    groups = {}
    for r in rows:
        groups.setdefault((summary.instance_label(summary.instance_key(r)), _rule_label(r)), []).append(r)
    out = []
    for (scheme, rule), rs in groups.items():
        n = sum(r["n_receivers"] for r in rs)
        out.append([rule, scheme, len(rs), _ratio(sum(r["hybrid_rays"] for r in rs), n),
                    _ratio(sum(r["n_acne"] + r["n_peterpan"] for r in rs), n),
                    _ratio(sum(r["hybrid_n_acne"] + r["hybrid_n_peterpan"] for r in rs), n),
                    sum(r["hybrid_n_ray_wrong"] for r in rs)])
    # a scheme's rules together, each rule's sweep by its rays (an undefined fraction last)
    rays = lambda x: x if metrics.defined(x) else float("inf")
    return sorted(out, key=lambda row: (row[1], row[0].split()[0], rays(row[3]), row[0]))


def _map_key(r) -> tuple:
    return r["scene"], r["light"], r["view"], r["resolution"]


def zero_error(rows: list) -> list:
    """Per (rule, origin, scheme instance): [rule, origin, scheme, maps, maps reaching zero error, the median
    and largest over those maps of the fewest rays per receiver that reach it (its sweep's least)]."""
    least = {}
    for r in rows:
        key = (r["hybrid_rule"], r["hybrid_origin"], summary.instance_label(summary.instance_key(r)))
        per_map = least.setdefault(key, {})
        best = per_map.setdefault(_map_key(r), metrics.UNDEFINED)
        if r["n_receivers"] and r["hybrid_n_acne"] + r["hybrid_n_peterpan"] == 0:
            per_map[_map_key(r)] = min(r["ray_fraction"], best) if metrics.defined(best) else r["ray_fraction"]
    out = []
    for (rule, origin, scheme), per_map in sorted(least.items()):
        reached = [x for x in per_map.values() if metrics.defined(x)]
        out.append([rule, origin, scheme, len(per_map), len(reached),
                    float(np.median(reached)) if reached else metrics.UNDEFINED,
                    max(reached) if reached else metrics.UNDEFINED])
    return out


POOLED_HEAD = ("rule", "scheme instance", "cases", "rays per receiver", "error before", "error after", "ray wrong")
ZERO_HEAD = ("rule", "origin", "scheme instance", "maps", "maps at zero error", "median rays per receiver",
             "max rays per receiver")


def _table(head, body) -> list:
    return ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"] + [
        "| " + " | ".join(md.cell(x) for x in row) + " |" for row in body]


def write_table(path, rows: list) -> bool:
    """hybrid.md from metrics.csv's rows; False (nothing written) without a hybrid case."""
    rows = hybrid_rows(rows)
    if not rows:
        return False
    lines = ["# Hybrid rays", "", INTRO, "", "## Pooled per rule and scheme instance", ""]
    lines += _table(POOLED_HEAD, pooled(rows))
    lines += ["", "## Rays for zero error", "", "Per map, the fewest rays per receiver of a rule's sweep that leave "
              "no error; over the maps where one does.", ""] + _table(ZERO_HEAD, zero_error(rows))
    with report.atomic(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return True


def curves(rows: list) -> dict:
    """{map key: {(scheme instance, rule, origin): [(rays per receiver, error rate)] sorted}}, each curve
    starting at the map alone (0 rays, its error rate)."""
    out = {}
    for r in rows:
        if not r["n_receivers"]:
            continue
        key = (summary.instance_label(summary.instance_key(r)), r["hybrid_rule"], r["hybrid_origin"])
        pts = out.setdefault(_map_key(r), {}).setdefault(key, {(0.0, r["error_rate"])})
        pts.add((r["ray_fraction"], r["hybrid_error_rate"]))
    return {m: {k: sorted(p) for k, p in c.items()} for m, c in out.items()}


def plot_jobs(folder: Path, rows: list) -> list:
    """(function, args) jobs drawing ``hybrid_<scene>_<light>_<view>_<R>.png``: each map's budget curves."""
    return [(draw, (Path(folder) / f"hybrid_{figures.slug('_'.join(map(str, m)))}.png",
                    f"{m[0]}, light {m[1]}, {m[2]} {m[3]}", c))
            for m, c in sorted(curves(hybrid_rows(rows)).items())]


# (line style, marker) per rule: the oracle's and the band's sweeps are nested sets of rays, drawn as
# lines; the classifier's parameters and the origin rules are no one sweep, drawn as points
STYLES = {"oracle": (":", "o"), "band": ("-", "."), "classifier": ("none", "x"), "all": ("none", "s")}


def draw(path: Path, title: str, series: dict):
    """Error rate against rays per receiver per (scheme instance, rule, origin): colour the scheme
    instance, style the rule (the oracle dotted: the floor); the legend names colours and styles."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    fig = Figure(figsize=(6.4, 4.2))
    glyph_cache.canvas(fig)           # matplotlib's text drawing, its work kept across figures
    ax = fig.subplots()
    schemes = sorted({k[0] for k in series})
    colour = lambda s: f"C{schemes.index(s) % 10}"
    for (scheme, rule, origin), pts in sorted(series.items()):
        x, y = zip(*pts)
        ls, mk = STYLES.get(rule, ("-", "."))
        ax.plot(x, y, linestyle=ls, marker=mk, markersize=3, linewidth=1, color=colour(scheme))
    ax.set_yscale("symlog", linthresh=1e-4)
    ax.set_ylim(0, 1)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("rays per receiver (0: the map alone)", fontsize=8)
    ax.set_ylabel("error rate after the rays", fontsize=8)
    ax.set_title(f"{title}: budget curves", fontsize=8)
    ax.tick_params(labelsize=7)
    handles = [Line2D([], [], color=colour(s), label=s[:40]) for s in schemes[:9]]
    handles += [Line2D([], [], color="0.3", linestyle=ls, marker=mk, markersize=3, label=rule)
                for rule, (ls, mk) in STYLES.items() if any(k[1] == rule for k in series)]
    ax.legend(handles=handles, fontsize=6, loc="upper right")
    fig.subplots_adjust(bottom=0.12, top=0.93, left=0.12, right=0.98)
    report.save_png(Path(path), lambda f, fmt: fig.savefig(f, dpi=80, format=fmt))


def html_view(rows: list) -> dict | None:
    """report.html's section on the run's hybrid cases (templates' hybrid.html: its words and two tables);
    None without one. Its curves are in Plots."""
    rows = hybrid_rows(rows)
    if not rows:
        return None
    table = lambda head, body: Table([(h, "text") for h in head], [Row([Cell(md.cell(x)) for x in r]) for r in body],
                                     box="wide")
    return {"intro": INTRO + " The budget curves are under Plots (plots/hybrid_*.png).",
            "pooled": table(POOLED_HEAD, pooled(rows)), "zero": table(ZERO_HEAD, zero_error(rows))}
