"""report.html: one self-contained page per run that opens from the file system (no server, no
network, no external script; images referenced relatively, inside the run's folder).

First screen: what accuracy costs per light type (dsm.report.frontier: the cheapest instance the data
cannot tell from the lowest error, its ties one click away, what a lower error costs), then the best
scheme per scene, light and resolution, then the per-instance summary
(dsm.report.summary); then a sortable, filterable case table (click a header to sort, a row to see its
error and shadow images), the plots, failures, and the run's versions and timing.

This module gathers the page's words, numbers and tables from the run's rows and files; the markup
is the template report.html (dsm.report.templates), which the other pages share.
"""
from __future__ import annotations

import json
import struct
from pathlib import Path

from ..truth import metrics
from . import frontier, io as report, summary
from ..core import labels
from .figures import CLASSES_GIF_COMMENT, display_paths, frames_path, image_paths, points_file, slug
from .sections import hybrid as hybrid_report
from .sections import virtual as virtual_report
from .sections import cache as cache_report
from .templates import Cell, Row, Table, render

CASE_COLUMNS = [("case", "case", "text"), ("scene", "scene", "text"), ("light", "light", "text"),
                ("view", "view", "text"), ("scheme", "scheme", "text"), ("params", "params", "text"),
                ("resolution", "R", "num"), ("filter", "filter", "text"), ("format", "format", "text"),
                ("n_receivers", "receivers", "num"), ("acne_rate", "acne rate", "num"),
                ("peterpan_rate", "peter-pan rate", "num"), ("error_rate", "error rate", "num"),
                ("build_ms", "build ms", "num"), ("lookup_ms", "lookup ms", "num")]
FILTER_COLUMNS = ("scene", "light", "view", "scheme", "resolution")

# the summary's numeric columns (key, heading) before and after its count of undefined rates
RATES = (("cases", "cases"), ("acne_pooled", "acne pooled"), ("acne_mean", "acne mean"),
         ("acne_median", "acne median"), ("acne_max", "acne max"), ("peterpan_pooled", "peter-pan pooled"),
         ("peterpan_mean", "peter-pan mean"), ("peterpan_median", "peter-pan median"),
         ("peterpan_max", "peter-pan max"), ("leak_pooled", "leak pooled"), ("error_pooled", "error pooled"),
         ("error_mean", "error mean"), ("error_median", "error median"), ("error_max", "error max"))
COSTS = (("build_ms", "build ms"), ("lookup_ms", "lookup ms"), ("best_in", "best in"))


def _num(x) -> tuple:
    """(data value, shown text) of a number; undefined: ('', '-')."""
    if not metrics.defined(x):
        return "", "-"
    if isinstance(x, int):
        return str(x), str(x)
    return repr(float(x)), (summary.rate(x) if abs(x) < 1 else (f"{x:.2f}" if x < 100 else f"{x:.1f}"))


def _cell(text, value=None) -> Cell:
    """A text cell; one shown otherwise than its value (a parameter label) has the exact value on hover."""
    return Cell(text, value, title=labels.params_title(value) if value not in (None, text) else None)


def _num_cell(x) -> Cell:
    """A number cell: its exact value sorts, its text is _num's."""
    value, text = _num(x)
    return Cell(text, value, num=True)


def _params_cell(params) -> Cell:
    """A params cell: the readable label shown, the exact text its value (sorting) and hover."""
    return _cell(labels.params_label(params), params)


def _best(rows) -> dict:
    """The best instance per scene, light (rows) and resolution (columns), with the rule's words."""
    resolutions, pivot = summary.best_pivot(rows)
    columns = [("scene", "text"), ("light", "text")] + [(f"R = {r}", "text") for r in resolutions]
    body = [Row([_cell(s), _cell(li)] + [_params_cell(summary.best_cell(cells.get(r))) for r in resolutions])
            for s, li, cells in pivot]
    return {"note": summary.BEST_DEFINITION, "table": Table(columns, body, box="wide")}    # scrolls in its box


def costs_view(points: list, empty: str) -> dict:
    """The first screen's answer (dsm.report.frontier): per light type its words, what a lower error
    costs and its ties as a table one click away; the measured times; ``empty`` where there are no points."""
    if not points:
        return {"answers": [], "times": [], "note": "", "empty": empty}
    found = frontier.answers(points)
    answers = []
    for a in found:
        head, why, more = frontier.answer_words(a)
        answers.append({"line": head, "why": why, "more": more, "tied": len(a["tied"]) - 1, "table": _tied_table(a)})
    return {"answers": answers, "times": frontier.time_lines(found), "note": frontier.DEFINITION, "empty": None}


def _tied_table(a: dict) -> Table:
    """The instances one light type's answer ties, cheapest first, with their mean error and costs."""
    columns = [("instance", "text"), ("error rate", "num"), ("bytes", "num"), ("rays", "num"), ("taps", "num"),
               ("build ms", "num"), ("lookup ms", "num")]
    body = [Row([_cell(c.instance), _num_cell(c.error), Cell(frontier.size(c.bytes), c.bytes, num=True),
                 Cell(f"{c.rays:,.0f}", c.rays, num=True), _num_cell(c.taps), _num_cell(c.build_ms),
                 _num_cell(c.lookup_ms)], cls="win" if c is a["chosen"] else None) for c in a["tied"]]
    return Table(columns, body, None, ("sortable",), "wide")


def _summary(rows) -> dict:
    """The per-instance summary table (dsm.report.summary), leaking beside acne and peter-panning in a run
    with [map] kind, and its definitions."""
    insts = summary.per_instance(rows)
    cols = summary.summary_columns(rows)
    split = summary.has_leak_split(rows)      # leaking beside acne and peter-panning, where the run splits it
    rates = [(k, h) for k, h in RATES if split or k != "leak_pooled"]
    columns = ([(c, "text") for c in cols] + [(h, "num") for _, h in rates]
               + [("undefined acne / peter-pan / error", "text")] + [(h, "num") for _, h in COSTS])
    body = []
    for s in insts:
        undefined = f"{s['acne_undefined']} / {s['peterpan_undefined']} / {s['error_undefined']}"
        cells = ([_params_cell(s[c]) if c == "params" else _cell(s[c]) for c in cols]
                 + [_num_cell(s[k]) for k, _ in rates] + [_cell(undefined)] + [_num_cell(s[k]) for k, _ in COSTS])
        body.append(Row(cells, cls="win" if s is insts[0] else None))
    multi = [c for c in cols if c not in ("scheme", "params")]
    extra = ", with " + " and ".join(multi) if multi else ""
    note = summary.DEFINITIONS.format(extra=extra) + (summary.LEAK_COLUMN_DEFINITION if split else "")
    return {"note": note.replace("*", ""), "table": Table(columns, body, "summary-table", ("sortable",), "wide")}


def summary_section(rows) -> str:
    """The per-instance summary section of report.html, alone."""
    return render("summary.html", summary=_summary(rows))


def _case_row(r: dict, out: Path, shown: set) -> Row:
    """A case's row: its cells, and what the filters and the viewer read (its images, where written)."""
    err, shadow = (p if (out / p).is_file() else "" for p in image_paths(r))
    nl, exact = (p if p in shown else "" for p in display_paths(r))
    gif = frames_path(r) if r.get("motion") and (out / frames_path(r)).is_file() else ""
    instance = f"{r['scheme']} {r['preset'] or labels.params_label(r['params'])}".strip()
    label = f"{r['scene']}, light {r['light']}, {r['view']}, {instance}, " \
            f"R = {r['resolution']}, {r['filter']}, {r['format']}"
    data = {k: r[k] for k in FILTER_COLUMNS} | {
        "case": r["case"], "err": err, "shadow": shadow, "label": label, "nl": nl, "exact": exact, "gif": gif,
        "gifkind": gif_kind(out / gif) if gif else ""}
    cells = [_num_cell(r[key]) if t == "num" else _params_cell(r[key]) if key == "params" else _cell(r[key])
             for key, _, t in CASE_COLUMNS]
    return Row(cells, data)


def _cases(rows, out: Path) -> dict:
    """The case table, and its filters' values."""
    shown = {p for r in {(r["scene"], r["light"]): r for r in rows}.values() for p in display_paths(r)
             if (out / p).is_file()}                # the display renders the run wrote (one pair a scene and light)
    filters = [(k, sorted({r[k] for r in rows}, key=lambda v: (isinstance(v, str), v))) for k in FILTER_COLUMNS]
    table = Table([(h, t) for _, h, t in CASE_COLUMNS], [_case_row(r, out, shown) for r in rows], "case-table",
                  ("sortable",), "scroll")
    return {"count": len(rows), "filters": filters, "table": table}


PLOT_KINDS = (
    ("vs_bias_", "Rates against each scheme's swept parameter (a column per unit)",
     "Acne (top row) and peter-panning (bottom row) against the scheme's parameter, at the view's largest "
     "resolution: acne falls and peter-panning rises as a bias grows; look for the value where both are low."),
    ("vs_resolution_", "Rates against map resolution",
     "A curve that does not fall as R grows is limited by its bias, not by the map's resolution."),
    ("vs_texels_", "Views at equal memory",
     "At the same total texels the lower line is the view that spends its memory better; the second row counts "
     "only receivers near a seam between faces."),
    ("pareto_", "What accuracy costs: error rate against memory",
     "Every case is a point at the bytes its lookup reads (hover to name it, click to open its images); the black "
     "line joins the cases on the frontier: no other case has at most their error, bytes and rays. Time is "
     "measured, in the case table, and never decides."),
    ("tradeoff_", "The exact trade-off of one bias, with the cases on it",
     "Lines: every acne and peter-panning pair one bias value reaches on this map (solid: a world bias, dotted: "
     "a texel bias); points: the run's nearest-filter cases (hover to name, click to open). A point above or "
     "right of its map's lines is accuracy a single bias would have had."),
    ("hybrid_", "Hybrid rays: error against rays per receiver",
     "Each map's budget curves ([hybrid]): 0 rays is the map alone; a colour per scheme instance, a style per "
     "rule; the dotted oracle is the floor (the fewest rays for each error), a curve far right of it spends "
     "rays where the map was right."),
    (cache_report.PLOT_PREFIX, "A cache's error against its update budget",
     "Per motion case with moving casters, the ghost + missing rate its cache policy leaves against the fraction "
     "of the map it re-casts per frame: none re-casts everything at no error; a policy lower and further left "
     "saves more for less error."),
)


def png_size(path: Path) -> tuple:
    """(width, height) of a PNG from its header (IHDR), without decoding it."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    return struct.unpack(">II", head[16:24])


def gif_kind(path: Path) -> str:
    """A motion GIF's frames: "classes" (the frames' class images, marked by CLASSES_GIF_COMMENT:
    images = "errors" or a run that did not complete) or "display" (three panels of display renders)."""
    with open(path, "rb") as fh:
        head = fh.read(4096)           # the comment precedes the first frame
    return "classes" if CLASSES_GIF_COMMENT in head else "display"


def _where_names(rows) -> dict:
    """A figure's file-name tag (scene_light_view, or scene_light) -> its words."""
    out = {}
    for r in rows:
        out[slug(f"{r['scene']}_{r['light']}_{r['view']}")] = f"{r['scene']}, light {r['light']}, {r['view']}"
        out[slug(f"{r['scene']}_{r['light']}")] = f"{r['scene']}, light {r['light']}, every view"
    return out


def _image_map(path: Path) -> tuple | None:
    """A figure's case points (figures.points_file) for its HTML image map: (map name, [(x, y, case, label)])."""
    f = points_file(path)
    if not f.is_file():
        return None
    points = json.loads(f.read_text(encoding="utf-8"))
    return "pts-" + path.stem, [(x, y, case, labels.params_label(label)) for x, y, case, label in points]


def _plots(out: Path, rows=()) -> list | None:
    """The figures in plots/ by kind (PLOT_KINDS), each with its size, words and image map; None: no plots."""
    plots = sorted((out / "plots").glob("*.png")) if (out / "plots").is_dir() else []
    if not plots:
        return None
    names = _where_names(rows)
    groups = []
    for prefix, title, look in PLOT_KINDS:
        figs = []
        for p in (p for p in plots if p.name.startswith(prefix)):
            w, h = png_size(p)
            where = names.get(p.stem[len(prefix):], p.stem[len(prefix):])
            figs.append({"name": p.name, "width": w, "height": h, "where": where, "imap": _image_map(p)})
        if figs:
            groups.append({"title": title, "look": look, "figures": figs})
    return groups


def _failed(run) -> list:
    """The run's failed and skipped parts (status, what, error)."""
    return [{"status": s["status"], "what": s["what"], "error": s.get("error", "")} for s in run.get("status", [])
            if s.get("status") in ("failed", "skipped")]


def _facts(run) -> list:
    """The run's state, config, versions and timing as (name, value) pairs."""
    timing = run.get("timing", {})
    items = [("state", run.get("state", "")), ("config", run.get("config_file", "")),
             ("variant", run.get("variant", "")), ("threads", run.get("threads", ""))]
    items += [(k, v) for k, v in run.get("versions", {}).items()]
    if "measure_s" in timing:
        items.append(("measuring (s)", f"{timing['measure_s']:.1f}"))
    items += [(f"G-buffer {k} (ms, cold)", f"{v:.1f}") for k, v in run.get("gbuffer_ms", {}).items()]
    items += [(f"rays: {k}", f"{v:,}") for k, v in run.get("rays", {}).items()]
    return items


def _counts(rows, run) -> str:
    """The page's line under its title: cases, scenes, pairs, measuring time, failures, state."""
    timing = run.get("timing", {})
    took = f", measured in {timing['measure_s']:.1f} s" if "measure_s" in timing else ""
    return (f"{len(rows)} cases, {len({r['scene'] for r in rows})} scenes, "
            f"{len({(r['scene'], r['light']) for r in rows})} scene-light pairs{took}; "
            f"{run.get('n_failed', 0)} failed, {run.get('n_empty', 0)} empty; state: {run.get('state', '?')}")


NO_COSTS = ("This run's rows carry no costs (a run from before dsm 0.6, or no case): no frontier. "
            "dsm run again for the answer by what accuracy costs.")


def write_html(path: Path, rows: list, run: dict, derived: dict | None = None):
    """report.html in ``path``'s folder (the run's), from its typed rows and run.json; ``derived``: what
    the run derived from its scene file (dsm.report.derivation), first."""
    path = Path(path)
    out = path.parent
    page = render("report.html", title=f"dsm: {run.get('experiment', out.name)}", counts=_counts(rows, run), derived=derived,
                  costs=costs_view(frontier.points_from_rows(rows), NO_COSTS),
                  answer=labels.params_label(summary.answer(rows)) if rows else None,
                  best=_best(rows) if rows else None, summary=_summary(rows) if rows else None,
                  failed=_failed(run), cases=_cases(rows, out) if rows else None,
                  virtual=virtual_report.html_table(rows), cache=cache_report.html_table(rows, out),
                  hybrid=hybrid_report.html_view(rows), plots=_plots(out, rows), facts=_facts(run))
    with report.atomic(path) as tmp:
        tmp.write_text(page, encoding="utf-8")
