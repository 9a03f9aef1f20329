"""report.html: one self-contained page per run that opens from the file system (no server, no
network, no external script; images referenced relatively, inside the run's folder).

First screen: the best scheme per scene, light and resolution, then the per-instance summary
(dsm.report.summary); then a sortable, filterable case table (click a header to sort, a row to see its
error and shadow images), the plots, failures, and the run's versions and timing.

Written with the standard library (html.escape and f-strings): one page with a fixed layout
gains nothing from a templating library's dependency; the script is plain JavaScript, with no
framework and no build step.
"""
from __future__ import annotations

import html
import json
import struct
from pathlib import Path

from ..truth import metrics
from . import io as report, labels, summary
from .figures import CLASSES_GIF_COMMENT, display_paths, frames_path, image_paths, points_file, slug
from .sections import hybrid as hybrid_report
from .sections import virtual as virtual_report

CASE_COLUMNS = [("case", "case", "text"), ("scene", "scene", "text"), ("light", "light", "text"),
                ("view", "view", "text"), ("scheme", "scheme", "text"), ("params", "params", "text"),
                ("resolution", "R", "num"), ("filter", "filter", "text"), ("format", "format", "text"),
                ("n_receivers", "receivers", "num"), ("acne_rate", "acne rate", "num"),
                ("peterpan_rate", "peter-pan rate", "num"), ("error_rate", "error rate", "num"),
                ("build_ms", "build ms", "num"), ("lookup_ms", "lookup ms", "num")]
FILTER_COLUMNS = ("scene", "light", "view", "scheme", "resolution")

CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:0 1.2em 2em;color:#222;max-width:1500px}
h1{font-size:1.35em;margin:.5em 0 .1em} h2{font-size:1.1em;margin:1.1em 0 .3em;border-bottom:1px solid #ccc}
.meta{color:#555;margin:0 0 .4em} .note{color:#555;font-size:12px;max-width:1100px}
table{border-collapse:collapse;font-size:12px} th,td{border:1px solid #ddd;padding:2px 6px;text-align:left}
td.n{text-align:right;font-variant-numeric:tabular-nums} th{background:#f2f2f2;position:sticky;top:0}
table.sortable th{cursor:pointer;user-select:none} th[aria-sort=ascending]::after{content:" \\25B2"}
th[aria-sort=descending]::after{content:" \\25BC"} tr.win td:first-child{font-weight:600}
#best td.cell{min-width:14em} .scroll{max-height:32em;overflow:auto;border:1px solid #ccc;display:inline-block;max-width:100%}
.wide{overflow-x:auto;max-width:100%;display:inline-block} .scroll,.wide,.figbox{box-sizing:border-box}
#case-table tbody tr{cursor:pointer} #case-table tbody tr:hover{background:#eef4ff}
#case-table tbody tr.sel{background:#dde8ff} .filters{margin:.3em 0} .filters label{margin-right:.8em}
#viewer{margin:.5em 0;min-height:2em} #viewer figure{display:inline-block;margin:0 8px 6px 0;vertical-align:top}
#viewer img{image-rendering:pixelated;width:320px;border:1px solid #999;display:block}
#viewer figcaption{font-size:12px;color:#333} .tint{position:relative;width:320px}
.tint img+img{position:absolute;left:0;top:0;mix-blend-mode:multiply;opacity:.85}
#viewer img[src$="display_nl.png"],#viewer img[src$="display_exact.png"]{image-rendering:auto}
#viewer figure.motion{display:block;max-width:100%} #viewer img.frames{width:auto;image-rendering:auto;max-width:none}
#viewer img.frames.classes{width:320px;image-rendering:pixelated}
.plots figure{margin:6px 0 14px;max-width:100%} .plots .figbox{overflow-x:auto;max-width:100%}
.plots img{max-width:none;border:1px solid #eee;cursor:zoom-in}
.plots figcaption{font-size:13px;color:#333;max-width:60em} .plots h3{font-size:1em;margin:.6em 0 .2em}
#zoom{position:fixed;inset:0;background:rgba(0,0,0,.6);overflow:auto;display:none;z-index:9;cursor:zoom-out}
#zoom img{background:#fff;margin:1em;max-width:none}
.sw{display:inline-block;width:.9em;height:.9em;border:1px solid #888;vertical-align:middle}
.bad{color:#a00} .answer{font-size:15px;font-weight:600;margin:.4em 0}
"""

SCRIPT = r"""
function cellValue(td, num) {
  const v = td.dataset.v !== undefined ? td.dataset.v : td.textContent;
  if (!num) return v;
  return v === '' || v === '-' ? NaN : parseFloat(v);
}
function sortBy(table, th) {
  const i = Array.from(th.parentNode.children).indexOf(th);
  const num = th.dataset.type === 'num';
  const asc = th.getAttribute('aria-sort') !== 'ascending';
  table.querySelectorAll('th').forEach(h => h.removeAttribute('aria-sort'));
  th.setAttribute('aria-sort', asc ? 'ascending' : 'descending');
  const body = table.tBodies[0];
  const rows = Array.from(body.rows);
  rows.sort((a, b) => {
    const x = cellValue(a.cells[i], num), y = cellValue(b.cells[i], num);
    if (num) {                      // undefined values (NaN) last, in either direction
      if (isNaN(x) || isNaN(y)) return isNaN(x) - isNaN(y);
      return asc ? x - y : y - x;
    }
    return asc ? x.localeCompare(y) : y.localeCompare(x);
  });
  const frag = document.createDocumentFragment();
  rows.forEach(r => frag.appendChild(r));
  body.appendChild(frag);
}
document.querySelectorAll('table.sortable').forEach(t =>
  t.querySelectorAll('thead th').forEach(th => th.addEventListener('click', () => sortBy(t, th))));

const cases = document.getElementById('case-table');
function applyFilters() {
  const sel = Array.from(document.querySelectorAll('.filters select'));
  const text = document.getElementById('filter-text').value.toLowerCase();
  let shown = 0;
  for (const tr of cases.tBodies[0].rows) {
    const ok = sel.every(s => s.value === '' || tr.dataset[s.name] === s.value) &&
               (text === '' || tr.textContent.toLowerCase().includes(text));
    tr.hidden = !ok;
    shown += ok;
  }
  document.getElementById('shown').textContent = shown;
}
document.querySelectorAll('.filters select, #filter-text').forEach(e => {
  e.addEventListener('input', applyFilters); e.addEventListener('change', applyFilters); });

const viewer = document.getElementById('viewer');
cases.tBodies[0].addEventListener('click', ev => {
  const tr = ev.target.closest('tr');
  if (!tr) return;
  cases.querySelectorAll('tr.sel').forEach(r => r.classList.remove('sel'));
  tr.classList.add('sel');
  viewer.replaceChildren();
  const cap = document.createElement('p');
  cap.textContent = 'case ' + tr.dataset.case + ': ' + tr.dataset.label;
  viewer.appendChild(cap);
  if (tr.dataset.gif) {     // a motion case: its frames (display renders), shown at their pixel size
    const fig = document.createElement('figure');
    fig.className = 'motion';
    const box = document.createElement('div');
    box.className = 'wide';
    const img = document.createElement('img');
    img.src = tr.dataset.gif; img.alt = 'frames of case ' + tr.dataset.case;
    img.className = tr.dataset.gifkind === 'classes' ? 'frames classes' : 'frames';
    box.appendChild(img);
    fig.appendChild(box);
    const words = document.createElement('figcaption');
    words.textContent = tr.dataset.gifkind === 'classes' ?
      'each frame: its error classes, one pixel per camera pixel (the class images: [report] images = "errors", ' +
      'or a run that did not complete)' :
      'each frame: the error classes over the display render (N.L), the exact shading, the shading under the map';
    fig.appendChild(words);
    viewer.appendChild(fig);
    return;
  }
  if (!tr.dataset.err && !tr.dataset.shadow) {
    cap.textContent += ' (no images were written: [report] images = "none")';
    return;
  }
  const base = tr.dataset.nl || tr.dataset.shadow;
  if (tr.dataset.err && base) {     // the classes (nearest-neighbour) tinted over the scene's shading: shapes stay readable
    const fig = document.createElement('figure');
    const box = document.createElement('div');
    box.className = 'tint';
    for (const [src, alt] of [[base, 'shading'], [tr.dataset.err, 'error classes']]) {
      const img = document.createElement('img');
      img.src = src; img.alt = alt + ' (tinted) of case ' + tr.dataset.case;
      box.appendChild(img);
    }
    fig.appendChild(box);
    const cap = document.createElement('figcaption');
    cap.textContent = tr.dataset.nl ? 'error classes over the display render (N.L)'
                                    : 'error classes tinted over the shading';
    fig.appendChild(cap);
    viewer.appendChild(fig);
  }
  const shown = [[tr.dataset.exact, 'exact image', 'exact shading (display render, V*)'],
                 [tr.dataset.shadow, 'shadow image', 'shading under the shadow map (Lambert, ambient in shadow)'],
                 [tr.dataset.err, 'error image', 'error classes (colours below)']];
  for (const [src, alt, words] of shown) {
    if (!src) continue;
    const fig = document.createElement('figure');
    const img = document.createElement('img');
    img.src = src; img.alt = alt + ' of case ' + tr.dataset.case; img.title = alt;
    fig.appendChild(img);
    const cap = document.createElement('figcaption');
    cap.textContent = words;
    fig.appendChild(cap);
    viewer.appendChild(fig);
  }
});
function showCase(id) {      // a plot's point: the case's row selected (filters cleared) and its images shown
  const tr = cases.querySelector('tbody tr[data-case="' + CSS.escape(id) + '"]');
  if (!tr) return;
  document.querySelectorAll('.filters select').forEach(s => s.value = '');
  document.getElementById('filter-text').value = '';
  applyFilters();
  tr.click();
  tr.scrollIntoView({block: 'nearest'});
  viewer.scrollIntoView({block: 'nearest'});
}
function fromHash() {
  const m = /^#case-(.+)$/.exec(decodeURIComponent(location.hash));
  if (m) showCase(m[1]);
}
window.addEventListener('hashchange', fromHash);
fromHash();
"""

# click a figure: shown enlarged (1.5 times its pixel size) over the page; click again to close it
ZOOM_SCRIPT = r"""
const zoom = document.getElementById('zoom');
if (zoom) {
  document.querySelectorAll('.plots img').forEach(img => img.addEventListener('click', () => {
    const big = zoom.querySelector('img');
    big.src = img.src; big.alt = img.alt + ' (enlarged)';
    big.style.width = (img.naturalWidth * 1.5) + 'px';
    zoom.style.display = 'block';
  }));
  zoom.addEventListener('click', () => { zoom.style.display = 'none'; });
}
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _num(x) -> tuple:
    """(data value, shown text) of a number; undefined: ('', '-')."""
    if not metrics.defined(x):
        return "", "-"
    if isinstance(x, int):
        return str(x), str(x)
    return repr(float(x)), (summary.rate(x) if abs(x) < 1 else (f"{x:.2f}" if x < 100 else f"{x:.1f}"))


def _td(text, value, num) -> str:
    cls = " class=n" if num else ""
    data = "" if value is None else f' data-v="{_e(value)}"'
    # a text cell shown otherwise than its value (a parameter label): the exact value on hover
    title = f' title="{_e(labels.params_title(value))}"' if not num and value not in (None, text) else ""
    return f"<td{cls}{data}{title}>{_e(text)}</td>"


def _params_cell(params) -> tuple:
    """A params cell: the readable label shown, the exact text its value (sorting) and hover."""
    return labels.params_label(params), params, False


def _table(head, rows, table_id=None, sortable=False) -> str:
    """head: [(text, type)]; rows: [(tr attributes, [(cell text, data value or None, numeric)])]."""
    out = [f"<table{f' id={_e(table_id)}' if table_id else ''}{' class=sortable' if sortable else ''}><thead><tr>"]
    out += [f"<th data-type={t}>{_e(h)}</th>" for h, t in head]
    out.append("</tr></thead><tbody>")
    for attrs, cells in rows:
        out.append(f"<tr{attrs}>" + "".join(_td(t, v, num) for t, v, num in cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _best_section(rows) -> str:
    resolutions, pivot = summary.best_pivot(rows)
    head = [("scene", "text"), ("light", "text")] + [(f"R = {r}", "text") for r in resolutions]
    body = [("", [(s, None, False), (l, None, False)] + [_params_cell(summary.best_cell(cells.get(r)))
                                                         for r in resolutions]) for s, l, cells in pivot]
    return (f"<section id=best><h2>Best scheme per scene, light and resolution</h2>"
            f"<p class=note>{_e(summary.BEST_DEFINITION)}</p>{_table(head, body)}</section>")


def summary_section(rows) -> str:
    """The per-instance summary table (dsm.report.summary), leaking beside acne and peter-panning in a
    run with [map] kind."""
    insts = summary.per_instance(rows)
    cols = summary.summary_columns(rows)
    split = summary.has_leak_split(rows)      # leaking beside acne and peter-panning, where the run splits it
    head = [(c, "text") for c in cols] + [(h, "num") for h in (
        "cases", "acne pooled", "acne mean", "acne median", "acne max", "peter-pan pooled", "peter-pan mean",
        "peter-pan median", "peter-pan max") + (("leak pooled",) if split else ()) + (
        "error pooled", "error mean", "error median", "error max")] + [
        ("undefined acne / peter-pan / error", "text")] + [(h, "num") for h in ("build ms", "lookup ms", "best in")]
    body = []
    for s in insts:
        cells = [_params_cell(s[c]) if c == "params" else (s[c], None, False) for c in cols]
        for k in ("cases", "acne_pooled", "acne_mean", "acne_median", "acne_max", "peterpan_pooled", "peterpan_mean",
                  "peterpan_median", "peterpan_max") + (("leak_pooled",) if split else ()) + (
                  "error_pooled", "error_mean", "error_median", "error_max", "undefined", "build_ms", "lookup_ms",
                  "best_in"):
            if k == "undefined":
                cells.append((f"{s['acne_undefined']} / {s['peterpan_undefined']} / {s['error_undefined']}", None,
                              False))
                continue
            v, t = _num(s[k])
            cells.append((t, v, True))
        body.append((" class=win" if s is insts[0] else "", cells))
    multi = [c for c in cols if c not in ("scheme", "params")]
    extra = ", with " + " and ".join(multi) if multi else ""
    note = summary.DEFINITIONS.format(extra=extra) + (summary.LEAK_COLUMN_DEFINITION if split else "")
    return (f"<section id=summary><h2>Per scheme instance (lowest pooled error first)</h2>"
            f"<p class=note>{_e(note.replace('*', ''))}</p>"
            f"<div class=wide>{_table(head, body, 'summary-table', True)}</div></section>")


def _case_section(rows, out: Path) -> str:
    head = [(h, t) for _, h, t in CASE_COLUMNS]
    body = []
    shown = {p for r in {(r["scene"], r["light"]): r for r in rows}.values() for p in display_paths(r)
             if (out / p).is_file()}                # the display renders the run wrote (one pair a scene and light)
    for r in rows:
        err, shadow = image_paths(r)
        err = err if (out / err).is_file() else ""
        shadow = shadow if (out / shadow).is_file() else ""
        nl, exact = (p if p in shown else "" for p in display_paths(r))
        gif = frames_path(r) if r.get("motion") and (out / frames_path(r)).is_file() else ""
        kind = gif_kind(out / gif) if gif else ""
        instance = f"{r['scheme']} {r['preset'] or labels.params_label(r['params'])}".strip()
        label = f"{r['scene']}, light {r['light']}, {r['view']}, {instance}, " \
                f"R = {r['resolution']}, {r['filter']}, {r['format']}"
        attrs = "".join(f' data-{k}="{_e(r[k])}"' for k in FILTER_COLUMNS) + \
            f' data-case="{_e(r["case"])}" data-err="{_e(err)}" data-shadow="{_e(shadow)}" data-label="{_e(label)}"' \
            f' data-nl="{_e(nl)}" data-exact="{_e(exact)}" data-gif="{_e(gif)}" data-gifkind="{kind}"'
        cells = []
        for key, _, t in CASE_COLUMNS:
            if t == "num":
                v, txt = _num(r[key])
                cells.append((txt, v, True))
            elif key == "params":
                cells.append(_params_cell(r[key]))
            else:
                cells.append((r[key], None, False))
        body.append((attrs, cells))
    selects = []
    for k in FILTER_COLUMNS:
        values = sorted({r[k] for r in rows}, key=lambda v: (isinstance(v, str), v))
        opts = "".join(f"<option value=\"{_e(v)}\">{_e(v)}</option>" for v in values)
        selects.append(f"<label>{_e(k)} <select name={k}><option value=\"\">all</option>{opts}</select></label>")
    legend = " ".join(f"<span class=sw style=\"background:rgb{tuple(int(c) for c in col)}\"></span> {_e(n)}"
                      for n, col in zip(metrics.CLASS_NAMES, metrics.CLASS_COLORS))
    return (f"<section id=cases><h2>Cases (<span id=shown>{len(rows)}</span> of {len(rows)} shown)</h2>"
            f"<p class=note>Click a header to sort (undefined values, '-', last), a row to see its error and shadow "
            f"images below the table. Rates: acne = n_acne / n_gt_lit, peter-pan = n_peterpan / n_gt_shadowed, "
            f"error = (acne + peter-pan) / receivers; times are kernel-time medians of the timed repeats (ms).</p>"
            f"<div class=filters>{''.join(selects)}<label>text <input id=filter-text size=18></label></div>"
            f"<div class=scroll>{_table(head, body, 'case-table', True)}</div>"
            f"<div id=viewer><p class=note>Error image colours: {legend}</p></div></section>")


PLOT_KINDS = (
    ("vs_bias_", "Rates against each scheme's swept parameter (a column per unit)",
     "Acne (top row) and peter-panning (bottom row) against the scheme's parameter, at the view's largest "
     "resolution: acne falls and peter-panning rises as a bias grows; look for the value where both are low."),
    ("vs_resolution_", "Rates against map resolution",
     "A curve that does not fall as R grows is limited by its bias, not by the map's resolution."),
    ("vs_texels_", "Views at equal memory",
     "At the same total texels the lower line is the view that spends its memory better; the second row counts "
     "only receivers near a seam between faces."),
    ("pareto_", "Cost of accuracy: error rate against time",
     "Every case is a point (hover to name it, click to open its images); the black line joins the cases that "
     "no other case beats in both time and error: the schemes on it are the ones worth their cost."),
    ("tradeoff_", "The exact trade-off of one bias, with the cases on it",
     "Lines: every acne and peter-panning pair one bias value reaches on this map (solid: a world bias, dotted: "
     "a texel bias); points: the run's nearest-filter cases (hover to name, click to open). A point above or "
     "right of its map's lines is accuracy a single bias would have had."),
    ("hybrid_", "Hybrid rays: error against rays per receiver",
     "Each map's budget curves ([hybrid]): 0 rays is the map alone; a colour per scheme instance, a style per "
     "rule; the dotted oracle is the floor (the fewest rays for each error), a curve far right of it spends "
     "rays where the map was right."),
)
ZOOM_BOX = "<div id=zoom title='click to close'><img alt=''></div>"


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


def _image_map(path: Path, name: str) -> str:
    """A figure's case points (figures.points_file) as an HTML image map: hover names, click opens the case."""
    f = points_file(path)
    if not f.is_file():
        return ""
    areas = "".join(f"<area shape=circle coords=\"{x},{y},6\" href=\"#case-{_e(case)}\" "
                    f"title=\"case {_e(case)}: {_e(labels.params_label(label))}\" alt=\"case {_e(case)}\">"
                    for x, y, case, label in json.loads(f.read_text(encoding="utf-8")))
    return f"<map name=\"{_e(name)}\">{areas}</map>"


def _figure_html(p: Path, where: str, look: str) -> str:
    """One figure at its pixel size (so its text reads at 9 points or more), its caption, its image map."""
    w, h = png_size(p)
    name = "pts-" + p.stem
    imap = _image_map(p, name)
    use = f" usemap=\"#{_e(name)}\"" if imap else ""
    return (f"<figure><div class=figbox><img loading=lazy src=\"plots/{_e(p.name)}\" width={w} height={h}{use} "
            f"alt=\"{_e(where)}\"></div>{imap}<figcaption><b>{_e(where)}</b>. {_e(look)} "
            f"<a href=\"plots/{_e(p.name)}\">{_e(p.name)}</a></figcaption></figure>")


def _plots_section(out: Path, rows=()) -> str:
    plots = sorted((out / "plots").glob("*.png")) if (out / "plots").is_dir() else []
    if not plots:
        return "<section id=plots><h2>Plots</h2><p class=note>No plots (the run did not complete).</p></section>"
    names = _where_names(rows)
    out_html = ["<section id=plots class=plots><h2>Plots</h2><p class=note>Each figure is shown at its own pixel "
                "size (its smallest text reads at 9 points); click one to enlarge it.</p>"]
    for prefix, title, look in PLOT_KINDS:
        ps = [p for p in plots if p.name.startswith(prefix)]
        if not ps:
            continue
        out_html.append(f"<details><summary>{_e(title)} ({len(ps)})</summary>")
        out_html += [_figure_html(p, names.get(p.stem[len(prefix):], p.stem[len(prefix):]), look) for p in ps]
        out_html.append("</details>")
    out_html.append("</section>" + ZOOM_BOX)
    return "".join(out_html)


def _status_section(run) -> str:
    bad = [s for s in run.get("status", []) if s.get("status") in ("failed", "skipped")]
    if not bad:
        return ""
    items = "".join(f"<li><b>{_e(s['status'])}</b>: {_e(s['what'])}: {_e(s.get('error', ''))}</li>" for s in bad)
    return f"<section id=status><h2 class=bad>Failed or skipped ({len(bad)})</h2><ul>{items}</ul></section>"


def _run_section(run) -> str:
    timing = run.get("timing", {})
    items = [("state", run.get("state", "")), ("config", run.get("config_file", "")),
             ("variant", run.get("variant", "")), ("threads", run.get("threads", ""))]
    items += [(k, v) for k, v in run.get("versions", {}).items()]
    if "measure_s" in timing:
        items.append(("measuring (s)", f"{timing['measure_s']:.1f}"))
    items += [(f"G-buffer {k} (ms, cold)", f"{v:.1f}") for k, v in run.get("gbuffer_ms", {}).items()]
    items += [(f"rays: {k}", f"{v:,}") for k, v in run.get("rays", {}).items()]
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in items)
    return f"<section id=run><h2>Run: versions and timing</h2><table>{rows}</table></section>"


def write_html(path: Path, rows: list, run: dict):
    """report.html in ``path``'s folder (the run's), from its typed rows and run.json."""
    path = Path(path)
    out = path.parent
    name = run.get("experiment", out.name)
    timing = run.get("timing", {})
    took = f", measured in {timing['measure_s']:.1f} s" if "measure_s" in timing else ""
    counts = (f"{len(rows)} cases, {len({r['scene'] for r in rows})} scenes, "
              f"{len({(r['scene'], r['light']) for r in rows})} scene-light pairs{took}; "
              f"{run.get('n_failed', 0)} failed, {run.get('n_empty', 0)} empty; state: {run.get('state', '?')}")
    body = [f"<h1>dsm: {_e(name)}</h1><p class=meta>{_e(counts)}. Files: <a href=table.md>table.md</a>, "
            f"<a href=metrics.csv>metrics.csv</a>, <a href=oracle.csv>oracle.csv</a>, <a href=run.json>run.json</a>.</p>"]
    if rows:
        body += [f"<p class=answer id=answer>{_e(labels.params_label(summary.answer(rows)))}</p>", _best_section(rows),
                 summary_section(rows)]
    body += [_status_section(run)]
    if rows:
        body.append(_case_section(rows, out))
        body.append(virtual_report.html_section(rows))
        body.append(hybrid_report.html_section(rows))
    body += [_plots_section(out, rows), _run_section(run)]
    page = (f"<!doctype html><html lang=en><head><meta charset=utf-8><title>dsm: {_e(name)}</title>"
            f"<meta name=viewport content=\"width=device-width\"><style>{CSS}</style></head><body>"
            + "".join(body) + (f"<script>{SCRIPT}</script>" if rows else "") + f"<script>{ZOOM_SCRIPT}</script>"
            "</body></html>\n")
    with report.atomic(path) as tmp:
        tmp.write_text(page, encoding="utf-8")

