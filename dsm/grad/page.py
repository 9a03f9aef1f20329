"""dsm grad's report.html: one page in the run's folder that opens from the file system (no server, no
network), composed from the folder's files after the measuring.

First the answer in words (dsm.grad.findings), then a sortable table per known CSV present (TABLES:
every cell the CSV's, numbers to 4 digits with the exact text on hover: dsm.report.csv_table), then
the figures present (FIGURES: at their pixel size, a caption that says what to look for), then any
other CSV in the folder as a link, and the run's versions and timing. A section is shown only when
its file exists: a plain ``dsm grad`` has the self-check alone. A new CSV or figure of dsm grad is
one line in TABLES or FIGURES; until then it is listed as a link. This module gathers the page's
words, tables and figures from the folder; the markup is the template grad.html (dsm.report.templates),
which the other pages share.
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

from ..report import csv_table
from ..report.html import png_size
from ..report.io import atomic, read_csv
from ..report.templates import Table, render
from . import findings, plots

PAGE = "report.html"
# (file, section id, title, what its rows are)
TABLES = (
    ("compare.csv", "compare", "Each technique against the truth",
     "Per technique and parameter: the AD derivative of the loss (ad) against the truth (reference: the central "
     "difference of the exact image, supersampled; reference_error its own error), rel_error = |ad - reference| / "
     "|reference|, the sign against the truth's, the cosine of the per-pixel gradient images, and the ms of one "
     "gradient (warm median, compile apart)."),
    ("projective.csv", "projective", "Mitsuba's projective integrators against the truth",
     "Mean and standard error over seeds; agrees: within three combined errors of the truth (else a finding, not a "
     "reference)."),
    ("equal_error.csv", "equal-error", "Cost at equal gradient error",
     "Per technique, parameter and projective integrator, over the pixels the integrator sees: the technique's "
     "gradient error (rel_error) and ms beside path tracing's samples per pixel (pt_spp) and ms at the same error, "
     "interpolated on its log-log error curve; time_ratio: path tracing's ms over the technique's. status 'already "
     "at the first spp': path tracing's fewest samples already err less, so pt_spp and time_ratio are upper bounds; "
     "undefined where path tracing never reached the error in the range or disagrees with the truth."),
    ("inverse.csv", "inverse", "The inverse task",
     "One row per technique, parameter and start: Adam from the truth + start_offset through the technique's image; "
     "final_error in the parameter's unit, success within the tolerance, converged_at the iteration from which it "
     "stayed within it."),
    ("selfcheck.csv", "selfcheck", "Self-check: AD against its own central difference and the closed form",
     "Per technique and parameter: the loss, AD (ad) and the technique's own central difference (fd; the step "
     "halved until no texel, pixel or antialiasing pair changes, changed_* count what still did), their relative gap ad_vs_fd, "
     "the closed form where one is known and ad_vs_closed."),
)
# (file, title, what to look for)
FIGURES = (
    ("relative_error.png", "Relative error against the truth, per technique and parameter",
     "A dot per parameter at the technique's relative error (symlog: linear below 1 %, so 0 shows); the further "
     "left, the closer to the truth. A technique without the antialiased map sits at 100 % where its gradient is 0."),
    ("gradients.png", "Per-pixel gradient images: the truth, each technique, each projective integrator",
     "Red: the pixel brightens as the parameter grows, blue: it darkens; each panel on its own scale (|max| in its "
     "title). A technique's image should put its mass where the truth's does, at the shadow's edge."),
    ("equal_error.png", "Cost at equal gradient error",
     "Path tracing's error against its time, and each technique's point: a technique left of the curve at its "
     "error is cheaper than path tracing at the same error."),
    ("inverse.png", "The inverse task: final error per start",
     "A line per technique through its starts' final errors (symlog); below the dashed tolerance a start "
     "succeeded. A line flat at the start's own offset did not move."),
)
WORDS = (("compare.csv", findings.compare_words), ("projective.csv", findings.projective_words),
         ("equal_error.csv", findings.equal_error_words), ("inverse.csv", findings.inverse_words),
         ("selfcheck.csv", findings.selfcheck_words))
DRAWN = ("relative_error.png", "inverse.png")     # the figures the report draws from the CSVs


def read_tables(out: Path) -> dict:
    """{file: (columns, rows)} of the known CSVs present in ``out``."""
    got = {}
    for name, *_ in TABLES:
        p = out / name
        if p.is_file():
            rows = read_csv(p)
            with open(p, newline="") as fh:
                columns = next(csv.reader(fh), [])      # an empty file: no columns, no rows
            got[name] = (columns, rows)
    return got


def draw_figures(out: Path, tables: dict, tolerance=None) -> dict:
    """relative_error.png and inverse.png from the CSVs present; returns the seconds each took."""
    parts = {}
    if tables.get("compare.csv", ((), []))[1]:
        t = time.perf_counter()
        plots.relative_error_figure(out / "relative_error.png", tables["compare.csv"][1],
                                    tables.get("projective.csv", ((), []))[1])
        parts["relative_error.png"] = time.perf_counter() - t
    if tables.get("inverse.csv", ((), []))[1]:
        t = time.perf_counter()
        plots.inverse_figure(out / "inverse.png", tables["inverse.csv"][1], tolerance)
        parts["inverse.png"] = time.perf_counter() - t
    return parts


def answer_words(tables: dict) -> list:
    """The answer in words: a paragraph per CSV that has one."""
    words = [fn(tables[name][1]) for name, fn in WORDS if name in tables and tables[name][1]]
    return [w for w in words if w]


def inverse_summary(rows) -> Table:
    """The inverse task's success per technique (rows) and parameter (columns), as 'k/n'."""
    params = list(findings.by(rows, "param"))
    cells = []
    for tech, rs in findings.by(rows, "technique").items():
        per = findings.by(rs, "param")
        cells.append({"technique": tech, **{f"{p} success": "{}/{}".format(*findings.success(per[p]))
                                             for p in params if p in per}})
    return csv_table.table(["technique"] + [f"{p} success" for p in params], cells, "inverse-summary")


def table_sections(tables: dict) -> list:
    """A section per known CSV present: its id, title, file, row count, note, rows (and the inverse task's
    summary)."""
    out = []
    for name, sid, title, note in TABLES:
        if name not in tables:
            continue
        columns, rows = tables[name]
        out.append({"id": sid, "title": title, "file": name, "count": findings.count(len(rows), "row"), "note": note,
                    "summary": inverse_summary(rows) if name == "inverse.csv" and rows else None,
                    "table": csv_table.table(columns, rows, "table-" + sid)})
    return out


def figures(out: Path) -> list:
    """The figures present, each with its pixel size, title and what to look for."""
    figs = []
    for name, title, look in FIGURES:
        if (out / name).is_file():
            w, h = png_size(out / name)
            figs.append({"name": name, "width": w, "height": h, "title": title, "look": look})
    return figs


def others(out: Path) -> list:
    """Any other CSV or PNG in the folder (a file this page does not know yet)."""
    known = {name for name, *_ in TABLES} | {name for name, *_ in FIGURES}
    return sorted(p.name for p in out.iterdir() if p.suffix in (".csv", ".png") and p.name not in known)


def run_facts(run: dict) -> list:
    """The run's config, options, versions and measuring time (the report's own time: grad.json)."""
    t = run.get("timing", {})
    items = [("config", run.get("config_file", "")), ("options", " ".join(run.get("options", [])) or "none"),
             ("variant", run.get("variant", ""))]
    items += list(run.get("versions", {}).items())
    items += [(f"{k.removesuffix('_s')} (s)", f"{v:.1f}") for k, v in t.items() if k.endswith("_s")]
    return items


def heading(run: dict) -> str:
    """The page's title line: scene, light, loss and sizes, from the run's ``gradient`` record."""
    g = run.get("gradient", {})
    if not g:
        return "dsm grad"
    return (f"dsm grad: {g.get('scene', '?')}, {g.get('light', '?')} light, loss {g.get('loss', '?')} "
            f"({g.get('loss_unit', '?')}); map {g.get('map_resolution', '?')}^2, image {g.get('image_resolution', '?')}^2")


def page_html(out: Path, tables: dict, run: dict) -> str:
    """The whole page."""
    files = [n for n in ("table.md", "compare.md", "inverse.md", "grad.json") if (out / n).is_file() or n == "grad.json"]
    return render("grad.html", title=heading(run), files=files, answers=answer_words(tables),
                  tables=table_sections(tables), figures=figures(out), others=others(out), facts=run_facts(run))


def write_report(out: Path, run: dict) -> dict:
    """Draw the report's figures and write report.html into ``out`` from its files; ``run`` is what grad.json
    records (config, options, versions, the gradient's scene, timing). Returns the seconds of each part."""
    out = Path(out)
    tables = read_tables(out)
    parts = draw_figures(out, tables, run.get("gradient", {}).get("inverse_tolerance"))
    t = time.perf_counter()
    with atomic(out / PAGE) as tmp:
        tmp.write_text(page_html(out, tables, run), encoding="utf-8")
    parts[PAGE] = time.perf_counter() - t
    return parts
