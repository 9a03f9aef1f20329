"""The leaderboard page: static HTML next to results.json and scale.png (no network), sortable like report.html."""
from __future__ import annotations

import html
import math
from pathlib import Path

from .. import prefilter
from ..report import labels
from ..report.html import CSS, SCRIPT
from ..schemes.presets import PRESETS
from . import bias_units, contenders, figure, ranking

LEAK_NOTE = (" Leak rate (pre-filtered maps only, '-' for the depth map's contenders): their receivers lit at "
             "least 2 texels inside the exact shadow on their own surface (n_leak; an outline error is never "
             "a leak) summed over the cases at the origin, over the summed shadowed receivers "
             "of V*. A pre-filtered contender (kind, an engine's preset of it where named, and blur; else the kind's "
             "defaults) has no cascades: its directional light gets one map.")


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
SORT_SCRIPT = SCRIPT.split("const cases")[0]      # report.html's header sort, without its case viewer
FAMILIES = ("engine preset", "scheme", "pre-filtered map", "tuned", "oracle")
FILTERS = ("family", "contender", "scene", "unit", "light")
# the page's own layout beside report.html's: tables in boxes that scroll sideways rather than run
# off the page, headers that wrap, the filters, the figure at its pixel size
PAGE_CSS = """
.wide{overflow-x:auto;max-width:100%} .wide th{white-space:normal;max-width:7em;vertical-align:bottom}
.filters label{margin-right:1em} .filters select{max-width:16em} tr[data-contender]{cursor:pointer}
.figbox{overflow-x:auto;max-width:100%} .figbox img{max-width:none}
"""
# the filters: a row is shown when every chosen value equals its data attribute of that name (a
# table whose rows lack the attribute ignores that filter); a click on a ranking row chooses its
# contender in the cases table
FILTER_SCRIPT = r"""
const selects = Array.from(document.querySelectorAll('.filters select'));
function applyFilters() {
  for (const table of document.querySelectorAll('table.filtered')) {
    let shown = 0;
    for (const tr of table.tBodies[0].rows) {
      const ok = selects.every(s => s.value === '' || tr.dataset[s.name] === undefined ||
                                    tr.dataset[s.name] === s.value);
      tr.hidden = !ok;
      shown += ok;
    }
    const count = document.getElementById(table.id + '-shown');
    if (count) count.textContent = shown;
  }
}
selects.forEach(s => s.addEventListener('change', applyFilters));
document.querySelectorAll('#ranking tbody tr').forEach(tr => tr.addEventListener('click', e => {
  if (e.target.closest('a')) return;          // the contender's name opens its page
  document.querySelector('.filters select[name=contender]').value = tr.dataset.contender;
  applyFilters();
  document.getElementById('cases').scrollIntoView();
}));
"""


def family(doc: dict, contender: str) -> str:
    """A contender's family (FAMILIES): the oracle, a tuned scheme, a pre-filtered map, an engine's preset,
    else a scheme at its defaults."""
    if contender == "oracle":
        return "oracle"
    if contender in doc.get("tuned", {}):
        return "tuned"
    if contender.split()[:1] and contender.split()[0] in prefilter.NAMES:
        return "pre-filtered map"
    return "engine preset" if contender in PRESETS else "scheme"


def fmt(v, digits=4) -> str:
    """A cell's text: numbers to ``digits`` significant digits, None as '-'."""
    if v is None:
        return "-"
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def row_attrs(values: dict) -> str:
    """A row's data attributes (the filters read them)."""
    return "".join(f' data-{k}="{html.escape(str(v), quote=True)}"' for k, v in values.items())


def table(head: list, rows: list, sortable=True, attrs=None, table_id=None, links=None, ids=None) -> str:
    """An HTML table: ``head`` the column titles, ``rows`` lists of cells (numbers right-aligned, sortable);
    ``attrs``: a dict of data attributes per row (the table is then filtered by the page's filters);
    ``links``: per row, {column: href} of the text cells that link; ``ids``: per row, its id (or None)."""
    num = [all(isinstance(r[i], (int, float)) or r[i] is None for r in rows) for i in range(len(head))]
    classes = " ".join((["sortable"] if sortable else []) + (["filtered"] if attrs is not None else []))
    ident = f" id={table_id}" if table_id else ""
    out = [f"<div class=wide><table{ident}{f' class={chr(34)}{classes}{chr(34)}' if classes else ''}><thead><tr>"]
    out += [f"<th data-type={'num' if n else 'text'}>{html.escape(h)}</th>" for h, n in zip(head, num)]
    out.append("</tr></thead><tbody>")
    for i, r in enumerate(rows):
        href = links[i] if links is not None else {}
        cells = [f"<td class=n data-v='{'' if v is None else v}'>{fmt(v)}</td>" if n else
                 f"<td>{link(html.escape(fmt(v)), href.get(j))}</td>" for j, (v, n) in enumerate(zip(r, num))]
        row_id = f" id={ids[i]}" if ids is not None and ids[i] else ""
        out.append(f"<tr{row_id}{row_attrs(attrs[i]) if attrs is not None else ''}>" + "".join(cells) + "</tr>")
    return "".join(out) + "</tbody></table></div>"


def link(text_html: str, href: str | None) -> str:
    """``text_html`` as a link to ``href`` (None: as it is)."""
    return text_html if href is None else f"<a href=\"{html.escape(href, quote=True)}\">{text_html}</a>"


def answer(doc: dict, ranked: list) -> str:
    """The page's opening: the ranking's top, the most scale-robust preset, the oracle's floor."""
    floor = ranking.oracle_floor(doc)
    top = ", ".join(f"{r['rank']}. {r['contender']} ({r['error']:.4f})" for r in ranked[:5])
    robust = ranking.most_scale_robust(ranked, among=set(PRESETS))
    if robust is None:
        robust_text = "Most scale-robust preset: none (no preset ran at more than one unit)."
    else:
        robust_text = (f"Most scale-robust preset: {robust['contender']} (mean spread of its error across cm, m and "
                       f"km: {robust['spread']:.4f}; its mean error rate {robust['error']:.4f}: a preset that fails "
                       "alike at every unit is robust by this measure, not good).")
    return (f"<p class=answer>Ranking (mean error rate over every scene, unit and light, at the origin): "
            f"{html.escape(top)}.</p>"
            f"<p class=answer>{html.escape(robust_text)}</p>" + far_answer(ranked) + prefiltered_answer(ranked) + tuned_answer(doc, ranked) +
            f"<p class=answer>Oracle floor: per-texel {floor['per_texel_objective']:.2g}, best single world bias "
            f"{floor['world_objective']:.4f}, best single texel bias {floor['texel_objective']:.4f}.</p>")


def far_answer(ranked: list) -> str:
    """The opening's line on the far-from-origin axis: the preset whose error moves least from the origin."""
    pool = [r for r in ranked if r["contender"] in PRESETS and r.get("far_change") is not None
            and not math.isnan(r["far_change"])]
    if not pool:
        return ""
    best = min(pool, key=lambda r: (abs(r["far_change"]), r["error"], r["contender"]))
    text = (f"Far from the origin: {best['contender']} moves least, its error rate {best['far_change']:+.4f} from the "
            f"origin to {list(best['far'])[-1]} (the map in float32 world coordinates; the exact side is exact; "
            "a preset that fails alike everywhere moves little: robust by this measure, not good).")
    return f"<p class=answer>{html.escape(text)}</p>"


def prefiltered_answer(ranked: list) -> str:
    """The opening's line on the pre-filtered maps: the best of them, its rank and leak rate."""
    pool = [r for r in ranked if r.get("leak") is not None]
    if not pool:
        return ""
    best = min(pool, key=lambda r: (r["error"], r["contender"]))    # a tie's rows are listed by name
    words = best["contender"].split()          # kind, [an engine's preset,] filter
    what = f"{words[1]}'s preset of {words[0]}" if len(words) == 3 else "at the kind's defaults"
    text = (f"Best pre-filtered map: {best['contender']} (rank {best['rank']}, error rate {best['error']:.4f}, "
            f"leak rate {best['leak']:.4f}, {what}).")
    return f"<p class=answer>{html.escape(text)}</p>"


def tuned_answer(doc: dict, ranked: list) -> str:
    """The opening's line on the best tuned scheme: its frozen values, rank and error."""
    pool = [r for r in ranked if r["contender"] in doc.get("tuned", {})]
    if not pool:
        return ""
    best = min(pool, key=lambda r: (r["error"], r["contender"]))
    t = doc["tuned"][best["contender"]]
    values = ", ".join(labels.params_label(f"{k}={v}").replace("=", " = ", 1) for k, v in t.items() if k != "name")
    text = (f"Best tuned scheme: {best['contender']} ({t['name']} with {values}; rank {best['rank']}, error rate "
            f"{best['error']:.4f}), tuned once on the suite's training views (its built-in scenes at metres under its "
            "three lights, from two cameras that are not the suite's) and frozen into the suite.")
    exact = ", ".join(f"{k} = {v}" for k, v in t.items() if k != "name")
    return f"<p class=answer title=\"{html.escape('exact: ' + exact, quote=True)}\">{html.escape(text)}</p>"


def grid_section(doc: dict) -> str:
    """One row per contender, a column per scene x unit (error rate averaged over the lights), the oracle row."""
    cells = ranking.error_by(doc, lambda r: (r["scene"], r["unit"]))
    cols = sorted({k for d in cells.values() for k in d}, key=lambda k: (k[0], ["cm", "m", "km"].index(k[1])))
    rows = [[c] + [cells[c].get(k) for k in cols] for c in sorted(cells)]
    attrs = [{"family": family(doc, c), "contender": c} for c in sorted(cells)]
    return "<h2>Error rate per scene and unit</h2>" + table(["contender"] + [f"{s} {u}" for s, u in cols], rows,
                                                             attrs=attrs)


def scale_section(doc: dict) -> str:
    """Per contender: its error rate against the unit and against the offset, as scale.png and as tables."""
    data = figure.series(doc)
    units, by_unit = data["unit"]
    out = ("<h2>Error rate against scale</h2><p class=note>Mean error rate over the scenes and lights (the oracle: "
           "its per-texel floor); the figure draws the tables' numbers.</p>"
           + figure_html(doc)
           + table(["contender"] + units, [[c] + v for c, v in by_unit.items()],
                   attrs=[{"family": family(doc, c), "contender": c} for c in by_unit]))
    if "offset" in data:
        offs, by_off = data["offset"]
        out += (f"<h3>Error rate against the offset (at {html.escape(doc['far_unit'])})</h3><p class=note>Each scene "
                "moved by the offset (world units), camera and lights with it; the engine holds positions in float32 "
                "world coordinates, so the map loses precision there; the exact visibility does not move.</p>"
                + table(["contender"] + offs, [[c] + v for c, v in by_off.items()],
                        attrs=[{"family": family(doc, c), "contender": c} for c in by_off]))
    return out


def figure_html(doc: dict) -> str:
    """scale.png at its pixel size (its text reads at 9 points), in a box that scrolls sideways where it
    is wider than the page."""
    return (f"<div class=figbox><img src={figure.FILE} alt='error rate against the scene unit and offset, per "
            "contender' data-shown-scale='1'></div>")


def filters_html(doc: dict) -> str:
    """The page's filters: a select per FILTERS key, its values from the cases at the origin."""
    recs = [r for r in doc["cases"] if ranking.at_origin(r)]
    values = {"family": [f for f in FAMILIES if any(family(doc, r["contender"]) == f for r in recs)],
              "contender": sorted({r["contender"] for r in recs})}
    for k in ("scene", "unit", "light"):
        values[k] = sorted({r[k] for r in recs}, key=lambda v: (["cm", "m", "km"].index(v) if k == "unit"
                                                                and v in ("cm", "m", "km") else 9, v))
    sel = "".join(f"<label>{k} <select name={k}><option value=''>all</option>"
                  + "".join(f"<option value=\"{html.escape(v, quote=True)}\">{html.escape(v)}</option>" for v in vs)
                  + "</select></label>" for k, vs in values.items())
    return (f"<div class=filters><b>Filter</b> {sel}</div><p class=note>The family and contender filters apply to "
            "every table; scene, unit and light to the cases table (the ranking pools them all). Click a ranking "
            "row to see its cases.</p>")


def cases_section(doc: dict) -> str:
    """Every case at the origin: a row per contender, scene, unit and light, filtered by the page's filters."""
    indexed = [(i, r) for i, r in enumerate(doc["cases"]) if ranking.at_origin(r) and r["contender"] != "oracle"]
    recs = [r for _, r in indexed]
    head = ["contender", "family", "scene", "unit", "light", "parameters", "error rate", "acne rate",
            "peter-pan rate", "FLIP", "leak rate", "receivers", "build ms", "lookup ms"]
    rows = [[r["contender"], family(doc, r["contender"]), r["scene"], r["unit"], r["light"],
             labels.params_label(r.get("params", "")), r["error_rate"], r["acne_rate"], r["peterpan_rate"],
             r.get("flip"), r.get("leak_rate"), r["n_receivers"], r["build_ms"], r["lookup_ms"]] for r in recs]
    attrs = [{k: (family(doc, r["contender"]) if k == "family" else r[k]) for k in FILTERS} for r in recs]
    return (f"<section id=cases><h2>Cases at the origin (<span id=case-list-shown>{len(rows)}</span> of "
            f"{len(rows)} shown)</h2><p class=note>Parameters to four significant digits (a depth-range step as "
            "2^-k); results.json holds them exactly. A contender's name opens its case's images.</p>"
            + table(head, rows, attrs=attrs, table_id="case-list", ids=[f"case-{i}" for i, _ in indexed],
                    links=[{0: f"{contenders.page_path(r['contender'])}#{contenders.case_anchor(i)}"}
                           for i, r in indexed])
            + "</section>")


def bias_section(doc: dict) -> str:
    """Each preset's bias in world units and texels at each unit, on the suite's first scene."""
    scene = doc["cases"][0]["scene"]
    rows = [[r["preset"], r["light"], r["unit"], r["texel_size"], r["depth_bias"], r["depth_bias_world"],
             r["depth_bias_texels"], r["normal_offset"], r["normal_offset_world"], r["normal_offset_texels"],
             r["error_rate"]] for r in bias_units.bias_rows(doc, scene)]
    head = ["preset", "light", "unit", "texel (world)", "depth bias", "depth world", "depth texels", "normal offset",
            "normal world", "normal texels", "error rate"]
    return (f"<h2>Preset biases in world units and texels ({html.escape(scene)})</h2><p class=note>A world-unit term "
            "is fixed as the scene grows: in texels it swings by 10^5 from cm to km. A texel term is scale-free. "
            "'range' terms (a fraction of the depth range) are shown as given.</p>" + table(head, rows))


def write_page(doc: dict, out: Path) -> Path:
    """Write ``leaderboard.html`` in ``out`` from a result document; returns its path."""
    ranked = ranking.ranking(doc)
    far = list(ranked[0]["far"])[1:] if ranked else []
    # the error at each offset is the offset table's (below): the ranking keeps its far change alone
    head = ["rank", "contender", "family", "error rate", "acne rate", "peter-pan rate", "scale spread", "FLIP",
            "leak rate", "flicker"] + (["far change"] if far else []) + ["build ms", "lookup ms"]
    rows = [[r["rank"], r["contender"], family(doc, r["contender"]), r["error"], r["acne"], r["peterpan"], r["spread"],
             r["flip"], r.get("leak"), r.get("flicker")] + ([r["far_change"]] if far else [])
            + [r["build_ms"], r["lookup_ms"]] for r in ranked]
    attrs = [{"family": family(doc, r["contender"]), "contender": r["contender"]} for r in ranked]
    m = doc["machine"]
    meta = (f"{doc['suite']} (sha256 {doc['suite_sha256'][:12]}), size {doc['size']}, dsm {doc['dsm_version']} "
            f"{doc['versions'].get('dsm_git_commit')}, {doc['variant']}, {m['cpu']} ({m['cores']} cores)")
    flip = (f" FLIP: the mean FLIP error (flip-evaluator, LDR, {doc['flip_ppd']:g} pixels per degree) of the "
            "shaded render under the contender's visibility against the same render under the exact one."
            if doc.get("flip_ppd") else "")
    body = (f"<h1>Shadow-bias leaderboard: {html.escape(doc['suite'])}</h1><p class=meta>{html.escape(meta)}</p>"
            + answer(doc, ranked) + "<h2>Ranking</h2><p class=note>" + html.escape(ranking.RULE_TEXT) + " "
            "Every column but the offsets' reads the cases at the origin. Far change: the error at the farthest "
            f"offset less the one at the origin (the error at each offset: the offset table below)."
            f"{html.escape(flip)}{html.escape(LEAK_NOTE)}{html.escape(flicker_note(doc))} Click a header to sort, a "
            "row to see its cases in the table below, a contender's name to open its page: each case's error "
            "classes and FLIP map, the worst first.</p>" + filters_html(doc)
            + table(head, rows, attrs=attrs, table_id="ranking",
                    links=[{1: contenders.page_path(r["contender"])} for r in ranked])
            + grid_section(doc) + scale_section(doc) + cases_section(doc) + bias_section(doc))
    Path(out).mkdir(parents=True, exist_ok=True)
    figure.write(doc, out)                      # scale.png, which the page shows
    contenders.write_pages(doc, out)            # the pages a ranking row's contender links to
    path = Path(out) / "leaderboard.html"
    path.write_text(f"<!doctype html><html><head><meta charset=utf-8><title>{html.escape(doc['suite'])}</title>"
                    f"<meta name=viewport content=\"width=device-width\"><style>{CSS}{PAGE_CSS}</style></head>"
                    f"<body>{body}<script>{SORT_SCRIPT}{FILTER_SCRIPT}</script></body></html>")
    return path
