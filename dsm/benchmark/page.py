"""The leaderboard page: static HTML next to results.json and scale.png (no network), sortable like report.html.

This module gathers the page's words, numbers and tables from the result document; the markup is the
template leaderboard.html (dsm.report.templates), which the other pages share.
"""
from __future__ import annotations

import math
from pathlib import Path

from .. import prefilter
from ..core import labels
from ..report.html import costs_view
from ..report.templates import Cell, Row, Table, render
from ..schemes.presets import PRESETS
from . import bias_units, contenders, costs, figure, ranking


def flicker_note(doc: dict) -> str:
    """The leaderboard's sentence on flicker: its motion as the result's suite ran it, and whether the
    pre-filtered maps are in it (from dsm-bench-4 on)."""
    mo = doc.get("flicker_motion") or {"offset": [0.25, 0.0, 0.0], "frames": 6}
    move = f"the camera dollies {math.hypot(*mo['offset']):g} m over {mo['frames']} frames"
    if mo.get("light") == "turn":
        move += f" while the sun turns {mo['light_angle']:g} degrees"
    pre = any(r["contender"].split()[0] in prefilter.NAMES for r in doc.get("flicker", []))
    who = "every contender" if pre else "depth contenders"
    tail = "" if pre else "; the pre-filtered maps refuse a motion ('-')"
    return (f" Flicker ({who}, on the suite's flicker scenes at metres): the mean over scenes, lights and frame pairs "
            "of the fraction of fixed surface points whose map class toggles while their exact visibility does not, "
            f"as {move}; it has no oracle floor (the oracles are per view){tail}.")


FAMILIES = ("engine preset", "scheme", "pre-filtered map", "hybrid rays", "tuned", "oracle")
FILTERS = ("family", "contender", "scene", "unit", "light")


def family(doc: dict, contender: str) -> str:
    """A contender's family (FAMILIES): the oracle, a tuned scheme, a pre-filtered map, hybrid rays, an engine's
    preset, else a scheme at its defaults."""
    if contender == "oracle":
        return "oracle"
    if contender in doc.get("tuned", {}):
        return "tuned"
    if contender.split()[:1] and contender.split()[0] in prefilter.NAMES:
        return "pre-filtered map"
    if contender.startswith(HYBRID_PREFIX):
        return "hybrid rays"
    return "engine preset" if contender in PRESETS else "scheme"


HYBRID_PREFIX = "hybrid "  # a hybrid contender's name (the suite's [[hybrid.contender]], dsm-bench-6 on)
NO_RAYS = "\u2014"      # the ray fraction's cell of a contender that traces no ray (a map alone)


def fmt(v, digits=4) -> str:
    """A cell's text: numbers to ``digits`` significant digits, None as '-'."""
    if v is None:
        return "-"
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def table(head: list, rows: list, attrs=None, table_id=None, links=None, ids=None) -> Table:
    """A sortable table: ``head`` the column titles, ``rows`` lists of cells (numbers right-aligned);
    ``attrs``: a dict of data attributes per row (the table is then filtered by the page's filters);
    ``links``: per row, {column: href} of the text cells that link; ``ids``: per row, its id (or None)."""
    num = [all(isinstance(r[i], (int, float)) or r[i] in (None, NO_RAYS) for r in rows) for i in range(len(head))]
    body = []
    for i, r in enumerate(rows):
        href = links[i] if links is not None else {}
        cells = [Cell(fmt(v), "" if v in (None, NO_RAYS) else v, True) if n else Cell(fmt(v), href=href.get(j))
                 for j, (v, n) in enumerate(zip(r, num))]
        body.append(Row(cells, attrs[i] if attrs is not None else {}, ids[i] if ids is not None else None))
    classes = ("sortable",) + (("filtered",) if attrs is not None else ())
    return Table([(h, "num" if n else "text") for h, n in zip(head, num)], body, table_id, classes, "wide")


def answers(doc: dict, ranked: list) -> list:
    """The page's opening, as (words, hover or None): with costs (results version 4) the best of each memory
    class and the other headlines among the contenders on the frontier; else the ranking's top by error
    alone; the most scale-robust preset, the far-from-origin, pre-filtered and tuned lines where the
    document has them, the oracle's floor and why it may sit above a contender."""
    front = costs.on_frontier(ranked, costs.contender_costs(doc)) if costs.has_costs(doc) else None
    pool = ranked if front is None else [r for r in ranked if r["contender"] in front]
    presets_on = [r for r in pool if r["contender"] in PRESETS]
    robust = ([robust_answer(pool, front is not None), far_answer(pool)] if front is None or presets_on
              else [no_preset_answer(pool)])
    lines = [class_answer(doc, ranked) if front is not None else top_answer(ranked), *robust,
             prefiltered_answer(ranked, front), tuned_answer(doc, ranked, front), floor_answer(doc)]
    return [line if isinstance(line, tuple) else (line, None) for line in lines if line is not None]


def top_answer(ranked: list) -> str:
    """The ranking's top five by error alone (a document without costs)."""
    top = ", ".join(f"{r['rank']}. {r['contender']} ({r['error']:.4f})" for r in ranked[:5])
    return f"Ranking (mean error rate over every scene, unit and light, at the origin): {top}."


def class_answer(doc: dict, ranked: list) -> str:
    """At equal cost: the first of each memory class (a tie at its head said as one), cheapest class first."""
    parts = []
    for k, rows in costs.classes(doc, ranked):
        first = [r["contender"] for r in rows if r["rank"] == 1]
        who = first[0] if len(first) == 1 else f"{len(first)} tied ({', '.join(first)})"
        parts.append(f"{costs.class_label(k)}: {who} ({rows[0]['error']:.4f})")
    return "Best in each memory class (a class is a factor of 2 of the bytes a lookup reads): " + "; ".join(parts) + "."


def robust_answer(pool: list, on_frontier: bool) -> str:
    """The most scale-robust preset, among the contenders on the frontier where the document has costs."""
    robust = ranking.most_scale_robust(pool, among=set(PRESETS))
    where = " on the frontier" if on_frontier else ""
    if robust is None:
        return (f"Most scale-robust preset{where}: none (no such preset ran at more than one unit). Scale "
                "robustness is the spread of a preset's error across cm, m and km: a preset that fails alike at "
                "every unit spreads little.")
    return (f"Most scale-robust preset{where}: {robust['contender']} (mean spread of its error across cm, m and "
            f"km: {robust['spread']:.4f}; its mean error rate {robust['error']:.4f}: a preset that fails alike at "
            "every unit is robust by this measure, not good).")


def no_preset_answer(pool: list) -> str:
    """Where no engine preset is on the frontier: so, and where the presets' robustness is read instead."""
    names = ", ".join(r["contender"] for r in pool)
    return (f"No engine preset is on the frontier (on it: {names}): every preset errs more than a contender of no "
            "more memory and rays. Their robustness to scale and to distance from the origin is in the ranking's "
            "scale spread and far change columns.")


def floor_answer(doc: dict) -> str:
    """The oracles' floor and what it bounds: a single depth bias on the suite's depth map, nearest lookup."""
    floor = ranking.oracle_floor(doc)
    return (f"Oracle floor: per-texel {floor['per_texel_objective']:.2g}, best single world bias "
            f"{floor['world_objective']:.4f}, best single texel bias {floor['texel_objective']:.4f}: the best any "
            "depth bias can do on the suite's depth map at its resolution with the nearest lookup. A contender that "
            "changes the map (a virtual map's finer pages, a pre-filtered map's moments, a normal offset that moves "
            "the lookup, a filter) is not bound by it and may sit below it.")


def far_answer(ranked: list) -> str | None:
    """The opening's line on the far-from-origin axis: the preset whose error moves least from the origin."""
    pool = [r for r in ranked if r["contender"] in PRESETS and r.get("far_change") is not None
            and not math.isnan(r["far_change"])]
    if not pool:
        return None
    best = min(pool, key=lambda r: (abs(r["far_change"]), r["error"], r["contender"]))
    return (f"Far from the origin: {best['contender']} moves least, its error rate {best['far_change']:+.4f} from the "
            f"origin to {list(best['far'])[-1]} (the map in float32 world coordinates; the exact side is exact; "
            "a preset that fails alike everywhere moves little: robust by this measure, not good).")


def frontier_words(name: str, front) -> str:
    """'; on the frontier' or '; not on the frontier' (nothing for a document without costs)."""
    return "" if front is None else ("; on the frontier" if name in front else "; not on the frontier")


def prefiltered_answer(ranked: list, front=None) -> str | None:
    """The opening's line on the pre-filtered maps: the best of them, its rank, leak rate and whether it is
    on the frontier (``front``: the contenders on it, None without costs)."""
    pool = [r for r in ranked if r.get("leak") is not None]
    if not pool:
        return None
    best = min(pool, key=lambda r: (r["error"], r["contender"]))    # a tie's rows are listed by name
    words = best["contender"].split()          # kind, [an engine's preset,] filter
    what = f"{words[1]}'s preset of {words[0]}" if len(words) == 3 else "at the kind's defaults"
    return (f"Best pre-filtered map: {best['contender']} (rank {best['rank']}, error rate {best['error']:.4f}, "
            f"leak rate {best['leak']:.4f}, {what}{frontier_words(best['contender'], front)}).")


def tuned_answer(doc: dict, ranked: list, front=None) -> tuple | None:
    """The opening's line on the best tuned scheme: its frozen values, rank and error; its exact values on hover."""
    pool = [r for r in ranked if r["contender"] in doc.get("tuned", {})]
    if not pool:
        return None
    best = min(pool, key=lambda r: (r["error"], r["contender"]))
    t = doc["tuned"][best["contender"]]
    values = ", ".join(labels.params_label(f"{k}={v}").replace("=", " = ", 1) for k, v in t.items() if k != "name")
    text = (f"Best tuned scheme: {best['contender']} ({t['name']} with {values}; rank {best['rank']}, error rate "
            f"{best['error']:.4f}{frontier_words(best['contender'], front)}), tuned once on the suite's training views (its built-in scenes at metres under its "
            "three lights, from two cameras that are not the suite's) and frozen into the suite.")
    return text, "exact: " + ", ".join(f"{k} = {v}" for k, v in t.items() if k != "name")


def filtered(doc: dict, contenders_of) -> list:
    """The data attributes the filters read (family, contender) of each row's contender."""
    return [{"family": family(doc, c), "contender": c} for c in contenders_of]


def grid(doc: dict) -> Table:
    """One row per contender, a column per scene x unit (error rate averaged over the lights), the oracle row."""
    cells = ranking.error_by(doc, lambda r: (r["scene"], r["unit"]))
    cols = sorted({k for d in cells.values() for k in d}, key=lambda k: (k[0], ["cm", "m", "km"].index(k[1])))
    rows = [[c] + [cells[c].get(k) for k in cols] for c in sorted(cells)]
    return table(["contender"] + [f"{s} {u}" for s, u in cols], rows, attrs=filtered(doc, sorted(cells)))


def scale(doc: dict) -> dict:
    """Per contender: its error rate against the unit and (where the suite moves scenes) against the offset,
    the tables scale.png draws."""
    data = figure.series(doc)
    units, by_unit = data["unit"]
    out = {"figure": figure.FILE, "far_unit": doc.get("far_unit"), "by_offset": None,
           "by_unit": table(["contender"] + units, [[c] + v for c, v in by_unit.items()],
                            attrs=filtered(doc, by_unit))}
    if "offset" in data:
        offs, by_off = data["offset"]
        out["by_offset"] = table(["contender"] + offs, [[c] + v for c, v in by_off.items()],
                                 attrs=filtered(doc, by_off))
    return out


def filters(doc: dict) -> list:
    """The page's filters: (FILTERS key, its values) from the cases at the origin."""
    recs = [r for r in doc["cases"] if ranking.at_origin(r)]
    values = {"family": [f for f in FAMILIES if any(family(doc, r["contender"]) == f for r in recs)],
              "contender": sorted({r["contender"] for r in recs})}
    for k in ("scene", "unit", "light"):
        values[k] = sorted({r[k] for r in recs}, key=lambda v: (["cm", "m", "km"].index(v) if k == "unit"
                                                                and v in ("cm", "m", "km") else 9, v))
    return list(values.items())


def cases(doc: dict) -> Table:
    """Every case at the origin: a row per contender, scene, unit and light, filtered by the page's filters;
    a contender's name links its card on its page."""
    indexed = [(i, r) for i, r in enumerate(doc["cases"]) if ranking.at_origin(r) and r["contender"] != "oracle"]
    recs = [r for _, r in indexed]
    head = ["contender", "family", "scene", "unit", "light", "parameters", "error rate", "ray fraction", "acne rate",
            "peter-pan rate", "FLIP", "leak rate", "receivers", "build ms", "lookup ms"]
    rows = [[r["contender"], family(doc, r["contender"]), r["scene"], r["unit"], r["light"],
             labels.params_label(r.get("params", "")), r["error_rate"], r.get("ray_fraction", NO_RAYS), r["acne_rate"],
             r["peterpan_rate"], r.get("flip"), r.get("leak_rate"), r["n_receivers"], r["build_ms"], r["lookup_ms"]]
            for r in recs]
    attrs = [{k: (family(doc, r["contender"]) if k == "family" else r[k]) for k in FILTERS} for r in recs]
    return table(head, rows, attrs=attrs, table_id="case-list", ids=[f"case-{i}" for i, _ in indexed],
                 links=[{0: f"{contenders.page_path(r['contender'])}#{contenders.case_anchor(i)}"}
                        for i, r in indexed])


def biases(doc: dict) -> dict:
    """Each preset's bias in world units and texels at each unit, on the suite's first scene."""
    scene = doc["cases"][0]["scene"]
    rows = [[r["preset"], r["light"], r["unit"], r["texel_size"], r["depth_bias"], r["depth_bias_world"],
             r["depth_bias_texels"], r["normal_offset"], r["normal_offset_world"], r["normal_offset_texels"],
             r["error_rate"]] for r in bias_units.bias_rows(doc, scene)]
    head = ["preset", "light", "unit", "texel (world)", "depth bias", "depth world", "depth texels", "normal offset",
            "normal world", "normal texels", "error rate"]
    return {"scene": scene, "table": table(head, rows)}


def ray_cell(row: dict):
    """A ranking row's ray fraction (rays per receiver at the origin), or NO_RAYS for a map alone."""
    return NO_RAYS if row.get("ray_fraction") is None else row["ray_fraction"]


def ranking_table(doc: dict, ranked: list) -> Table:
    """The ranking: a row per contender, its name linking its page; the far change where the suite moves scenes
    (the error at each offset is the offset table's). With costs (results version 4): grouped into memory
    classes, cheapest first, each ranked inside by the ranking's rule, with bytes, rays, taps and the frontier."""
    far = list(ranked[0]["far"])[1:] if ranked else []
    tail = ["scale spread", "FLIP", "leak rate", "flicker"] + (["far change"] if far else []) + ["build ms", "lookup ms"]
    values = lambda r: ([r["spread"], r["flip"], r.get("leak"), r.get("flicker")] + ([r["far_change"]] if far else [])
                        + [r["build_ms"], r["lookup_ms"]])
    if not costs.has_costs(doc):
        head = ["rank", "contender", "family", "error rate", "ray fraction", "acne rate", "peter-pan rate"] + tail
        rows = [[r["rank"], r["contender"], family(doc, r["contender"]), r["error"], ray_cell(r), r["acne"],
                 r["peterpan"]] + values(r) for r in ranked]
        at = 1
    else:
        ranked = [dict(r, memory=costs.class_label(k)) for k, rs in costs.classes(doc, ranked) for r in rs]
        head = ["memory class", "rank in class", "contender", "family", "frontier", "error rate", "ray fraction",
                "acne rate", "peter-pan rate", "MiB read", "rays", "taps"] + tail
        rows = [[r["memory"], r["rank"], r["contender"], family(doc, r["contender"]),
                 "yes" if r["on_frontier"] else "no", r["error"], ray_cell(r), r["acne"], r["peterpan"],
                 r["bytes"] / 2 ** 20, r["rays"], r["taps"]] + values(r) for r in ranked]
        at = 2
    return table(head, rows, attrs=filtered(doc, [r["contender"] for r in ranked]), table_id="ranking",
                 links=[{at: contenders.page_path(r["contender"])} for r in ranked])


def meta(doc: dict) -> str:
    """The line under the title: the suite and its hash, size, dsm's version and commit, variant, machine."""
    m = doc["machine"]
    return (f"{doc['suite']} (sha256 {doc['suite_sha256'][:12]}), size {doc['size']}, dsm {doc['dsm_version']} "
            f"{doc['versions'].get('dsm_git_commit')}, {doc['variant']}, {m['cpu']} ({m['cores']} cores)")


def context(doc: dict) -> dict:
    """What leaderboard.html is rendered with, from a result document."""
    ranked = ranking.ranking(doc)
    flip = (f" FLIP: the mean FLIP error (flip-evaluator, LDR, {doc['flip_ppd']:g} pixels per degree) of the "
            "shaded render under the contender's visibility against the same render under the exact one."
            if doc.get("flip_ppd") else "")
    no_costs = (f"This results.json (results_version {doc.get('results_version', 1)}) records no costs: the ranking "
                "below is by error alone. A benchmark of this dsm records each case's bytes, rays and taps.")
    return {"title": doc["suite"], "meta": meta(doc), "answers": answers(doc, ranked), "rule": ranking.RULE_TEXT,
            "costs": costs_view(costs.points(doc) if costs.has_costs(doc) else [], no_costs),
            "classed": costs.has_costs(doc),
            "flip": flip, "flicker": flicker_note(doc), "filters": filters(doc), "ranking": ranking_table(doc, ranked),
            "grid": grid(doc), "scale": scale(doc), "cases": cases(doc), "bias": biases(doc)}


def write_page(doc: dict, out: Path) -> Path:
    """Write ``leaderboard.html`` in ``out`` from a result document; returns its path."""
    page = render("leaderboard.html", **context(doc))
    Path(out).mkdir(parents=True, exist_ok=True)
    figure.write(doc, out)                      # scale.png, which the page shows
    contenders.write_pages(doc, out)            # the pages a ranking row's contender links to
    path = Path(out) / "leaderboard.html"
    path.write_text(page)
    return path
