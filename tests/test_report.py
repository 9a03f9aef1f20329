"""The report a person reads: the summary's definitions against a numpy recomputation from
metrics.csv, pooled against mean, undefined rates left out and counted, one unit per plot panel,
``dsm report DIR`` reproducing table.md, the comparison of two runs, and ``[report] images``."""
import csv
import json
import math
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import base_config

TINY = base_config(
    experiment={"name": "report_test"}, camera={"resolution": [40, 40]},
    # the lone plane has no shadow: its peter-panning rates are undefined
    scene=[{"builtin": "plane"}, {"builtin": "plane_box"}], map={"resolution": [32, 64]},
    scheme=[{"name": "none"}, {"name": "constant", "bias": ["0.5 texel", "2 texel", 0.05]}, {"name": "adaptive"}])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    import dsm
    return dsm.run(TINY, out=tmp_path_factory.mktemp("report") / "run")


def _csv(path):
    """metrics.csv read here, apart from the code under test: numbers as float64, '' as NaN."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    num = lambda v: float(v) if v != "" else np.nan
    return rows, num


@pytest.mark.slow
def test_summary_matches_a_numpy_recomputation(run):
    from dsm.report import io as report, summary
    raw, num = _csv(run.out / "metrics.csv")
    got = {s["key"]: s for s in summary.per_instance(report.read_rows(run.out / "metrics.csv"))}
    keys = sorted({(r["scheme"], r["preset"] or r["params"]) for r in raw})
    assert set(got) == set(keys) and len(keys) == 5
    # situations (scene, light, view, resolution): a lowest error rate alone wins; a tie is no one's win
    sit = {}
    for r in raw:
        sit.setdefault((r["scene"], r["light"], r["view"], r["resolution"]), []).append(r)
    wins = {k: 0 for k in keys}
    for rs in sit.values():
        e = np.array([num(r["error_rate"]) for r in rs])
        at_min = [r for r, x in zip(rs, e) if not np.isnan(x) and x == np.nanmin(e)]
        if len(at_min) == 1:
            wins[(at_min[0]["scheme"], at_min[0]["preset"] or at_min[0]["params"])] += 1
    for k in keys:
        rs = [r for r in raw if (r["scheme"], r["preset"] or r["params"]) == k]
        col = lambda c: np.array([num(r[c]) for r in rs], np.float64)
        s = got[k]
        assert s["cases"] == len(rs)
        assert s["acne_pooled"] == pytest.approx(col("n_acne").sum() / col("n_gt_lit").sum(), rel=1e-12)
        assert s["peterpan_pooled"] == pytest.approx(col("n_peterpan").sum() / col("n_gt_shadowed").sum(), rel=1e-12)
        assert s["error_pooled"] == pytest.approx((col("n_acne") + col("n_peterpan")).sum() / col("n_receivers").sum(),
                                                  rel=1e-12)
        for tag, c in (("acne", "acne_rate"), ("peterpan", "peterpan_rate"), ("error", "error_rate")):
            v = col(c)
            assert s[f"{tag}_undefined"] == int(np.isnan(v).sum())
            assert s[f"{tag}_mean"] == pytest.approx(np.nanmean(v), rel=1e-12)
            assert s[f"{tag}_median"] == pytest.approx(np.nanmedian(v), rel=1e-12)
            assert s[f"{tag}_max"] == pytest.approx(np.nanmax(v), rel=1e-12)
        assert s["build_ms"] == pytest.approx(col("build_ms").mean(), rel=1e-12)
        assert s["lookup_ms"] == pytest.approx(col("lookup_ms").mean(), rel=1e-12)
        assert s["best_in"] == wins[k]
        # the lone plane's cases: no truly shadowed receiver, so peter-panning is undefined there, and counted
        assert s["peterpan_undefined"] == sum(1 for r in rs if r["scene"] == "plane") == 2
    # the table is sorted by pooled error rate and table.md starts with it
    order = [s["error_pooled"] for s in summary.per_instance(report.read_rows(run.out / "metrics.csv"))]
    assert order == sorted(order)
    text = (run.out / "table.md").read_text()
    assert text.index("## Summary") < text.index("## Best per scene, light and resolution") < text.index("## Cases")
    assert "errors summed over the cases divided by the receivers summed" in text
    first = summary.per_instance(report.read_rows(run.out / "metrics.csv"))[0]
    assert f"| {summary.rate(first['error_pooled'])} |" in text


def test_pooled_is_not_the_mean_and_undefined_rates_are_left_out():
    """Two cases of one scheme: 1 of 10 lit receivers in acne, then 90 of 100; the third case has
    no lit receiver. Pooled acne = 91 / 110; the mean of the per-case rates = (0.1 + 0.9) / 2."""
    from dsm.report import summary
    nan = math.nan
    base = {"scene": "s", "light": "l", "view": "v", "scheme": "x", "preset": "", "params": "", "filter": "nearest",
            "format": "float32", "build_ms": 1.0, "lookup_ms": 2.0}
    rows = [dict(base, resolution=1, n_acne=1, n_gt_lit=10, n_peterpan=0, n_gt_shadowed=5, n_receivers=15,
                 acne_rate=0.1, peterpan_rate=0.0, error_rate=1 / 15),
            dict(base, resolution=2, n_acne=90, n_gt_lit=100, n_peterpan=1, n_gt_shadowed=4, n_receivers=104,
                 acne_rate=0.9, peterpan_rate=0.25, error_rate=91 / 104),
            dict(base, resolution=3, n_acne=0, n_gt_lit=0, n_peterpan=2, n_gt_shadowed=4, n_receivers=4,
                 acne_rate=nan, peterpan_rate=0.5, error_rate=0.5)]
    s = summary.per_instance(rows)[0]
    assert s["acne_pooled"] == pytest.approx(91 / 110)
    assert s["acne_mean"] == pytest.approx(0.5) and s["acne_median"] == pytest.approx(0.5)
    assert s["acne_max"] == pytest.approx(0.9) and s["acne_undefined"] == 1
    assert s["peterpan_pooled"] == pytest.approx(3 / 13) and s["peterpan_undefined"] == 0
    assert s["error_pooled"] == pytest.approx(94 / 123)
    # no receiver at all: every pooled rate undefined, and a dash in the table
    empty = dict(base, resolution=1, n_acne=0, n_gt_lit=0, n_peterpan=0, n_gt_shadowed=0, n_receivers=0,
                 acne_rate=nan, peterpan_rate=nan, error_rate=nan, scheme="y")
    t = {x["scheme"]: x for x in summary.per_instance(rows + [empty])}["y"]
    assert math.isnan(t["error_pooled"]) and t["error_undefined"] == 1 and t["best_in"] == 0
    assert any(line.startswith("| y |") and "| - |" in line for line in summary.summary_md(rows + [empty]))


def _rows(specs):
    """Synthetic case rows: (scheme, params, sweep_key, sweep_value, acne, peter-pan, resolution)."""
    out = []
    for i, (scheme, params, key, value, a, p, res) in enumerate(specs):
        out.append({"case": f"{i:04d}", "scene": "s", "light": "0:directional", "view": "orthographic",
                    "scheme": scheme, "preset": "", "params": params, "resolution": res, "total_texels": res * res,
                    "filter": "nearest", "format": "float32", "culling": "none", "acne_rate": a, "peterpan_rate": p,
                    "error_rate": (a + p) / 2, "seam_error_rate": math.nan, "build_ms": 1.0 + i, "lookup_ms": 0.5,
                    "sweep_key": key, "sweep_value": value, "n_receivers": 1000, "n_acne": round(500 * a),
                    "n_peterpan": round(500 * p), "map_bytes": 4 * res * res, "page_table_bytes": 0,
                    "map_rays": res * res, "taps": 1.0})
    return out


def test_plots_have_one_unit_per_panel_symlog_rates_and_short_legends(tmp_path):
    from dsm.report import figures
    specs = []
    for v in (0.5, 2.0):
        specs.append(("constant", f"bias={v:g} texel", "bias [texel]", v, 0.1 / v, 0.0, 64))
        specs.append(("normal_offset", f"offset={v:g} texel bias=0", "offset [texel]", v, 0.01 / v, 0.001 * v, 64))
    for v in (0.01, 0.05):
        specs.append(("constant", f"bias={v:g}", "bias [world]", v, 0.001, 0.0, 64))
    for v in (1e-4, 1e-3):
        specs.append(("adaptive", f"K={v:g}", "K", v, 0.0, 0.0001, 64))
    specs.append(("none", "", "", 0.0, 0.5, 0.0, 64))
    # ten instances at two resolutions: more than eight legend entries in all
    for k in range(10):
        for res in (32, 64):
            specs.append(("normal_angle", f"bias={k} texel max=8 texel", "bias [texel]", float(k), 0.01, 0.02, res))
    jobs = figures.plot_jobs(tmp_path, _rows(specs))
    byname = {a[0].name.split("_s_")[0]: (fn, a) for fn, a in jobs}
    fn, args = byname["vs_bias"]
    units = [c[1] for c in args[2]]
    # texel (constant, normal_offset, normal_angle: 12 series, two columns), world, K: one unit per column
    assert sorted(set(units)) == ["K", "parameter value [texel]", "parameter value [world]"]
    for title, xlabel, series, _ in args[2]:
        unit = xlabel.split("[")[-1].rstrip("]") if "[" in xlabel else xlabel
        for label in series:
            rows = [r for r in _rows(specs) if label.startswith(r["scheme"] + ":")
                    and (r["sweep_key"].split(" [")[-1].rstrip("]") == unit)]
            assert rows, (label, unit)
    fig = fn(*args)
    for ax in fig.axes:
        assert ax.get_yscale() == "symlog" and ax.get_ylim() == (0, 1)
        assert len(getattr(ax, "legend_texts", ())) <= figures.MAX_LEGEND
    assert "s, light 0:directional, orthographic, R = 64" in fig._suptitle.get_text()
    fn, args = byname["vs_resolution"]
    fig = fn(*args)
    legends = [len(ax.legend_texts) for ax in fig.axes if getattr(ax, "legend_texts", None)]
    assert sum(legends) == 10 and max(legends) <= figures.MAX_LEGEND
    # every series' label is in the figure, drawn (the legend's one text of many lines)
    drawn = "\n".join(t.get_text() for t in fig.texts)
    assert all(f"normal_angle bias={k} texel max=8 texel" in drawn for k in range(10))
    fn, args = byname["pareto"]
    fig = fn(*args)
    assert all(ax.get_xscale() == "log" and ax.get_yscale() == "symlog" for ax in fig.axes)
    assert (tmp_path / "vs_bias_s_0_directional_orthographic.png").is_file()


def _strokes(ax) -> list:
    """(RGBA colour, vertices, dashed) of every curve drawn in ``ax``: its lines and line collections
    (not the tick marks, which are markers without a line)."""
    from matplotlib.collections import LineCollection
    out = [(ln.get_color(), ln.get_xydata(), ln.get_linestyle() not in ("-", "solid"))
           for ln in ax.get_lines() if ln.get_linestyle() != "None"]
    for col in ax.collections:
        if isinstance(col, LineCollection):
            styles = col.get_linestyle() * len(col.get_segments()) if len(col.get_linestyle()) == 1 else col.get_linestyle()
            out += [(c, seg, dash[1] is not None) for c, seg, dash in zip(col.get_colors(), col.get_segments(), styles)]
    return out


# Okabe & Ito's colour-blind-safe palette (Color Universal Design, 2008), less its yellow and black
OKABE_ITO = ("#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7")


def test_series_styles_tell_24_series_apart_by_colour_and_shape():
    """Series k < 24 differ in their (colour, marker, dash); every colour is the palette's; a marker
    and dash change with each pass over the six colours, so no two series are told by colour alone."""
    from dsm.report import figures
    styles = [figures.style(k) for k in range(24)]
    assert len({(s["color"], s["marker"], s["ls"]) for s in styles}) == 24
    assert {s["color"] for s in styles} == set(OKABE_ITO)
    assert all(styles[k]["marker"] != styles[k + 6]["marker"] and styles[k]["ls"] != styles[k + 6]["ls"]
               for k in range(18))


def _texts_fit(fig, min_points):
    """Every text of a drawn figure (its Texts and tick-label artists): (smallest size in points,
    texts whose box leaves the figure)."""
    from matplotlib.text import Text
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    sizes, out = [], []
    for t in fig.findobj(Text):
        if t.get_text() and t.get_visible():
            sizes.append(t.get_fontsize())
            b = t.get_window_extent(r)
            if b.x0 < -1 or b.y0 < -1 or b.x1 > fig.bbox.x1 + 1 or b.y1 > fig.bbox.y1 + 1:
                out.append(t.get_text()[:40])
    # the tick labels: one artist a panel (dsm.report.canvas.tick_labels), its font in ``prop``
    sizes += [a.prop.get_size_in_points() for a in fig.findobj(lambda a: hasattr(a, "texts") and hasattr(a, "prop"))]
    return min(sizes), out


def test_consolidated_legends_name_each_map_and_instance_once(tmp_path):
    """The trade-off figure: one legend entry per map (not one per curve), on the first panel
    only when every panel holds the same maps; views at equal memory: one entry per instance
    (not per view), every instance named, the line style of each view said in the title."""
    from matplotlib.colors import to_rgba

    from dsm.report import figures
    curve = (np.array([0.0, 0.1, 1.0]), np.array([1.0, 0.01, 0.0]))
    maps = [("float32", 0, curve, curve, [(0.01, 0.1)]), ("float32 back_closed", 1, curve, curve, [])]
    fig = figures.draw_tradeoff(tmp_path / "t.png", "s", [("R = 64", maps), ("R = 128", maps)])
    assert [getattr(ax, "legend_texts", []) for ax in fig.axes] == [["float32", "float32 back_closed"], []]
    assert "solid: one world bias, dotted: one k texel" in " ".join(fig._suptitle.get_text().split())
    # no text below figures.MIN_FONT points (9 as report.html shows it), none outside the figure
    assert _texts_fit(fig, figures.MIN_FONT) == (figures.MIN_FONT, [])
    # a map's two curves share its colour: solid (world) and dotted (texel)
    styles = {(tuple(c), dashed) for c, _, dashed in _strokes(fig.axes[0])}
    assert styles == {(to_rgba(OKABE_ITO[k]), dashed) for k in (0, 1) for dashed in (False, True)}
    rows = []
    for view in ("cube", "dual_paraboloid"):
        for k in range(10):
            for res in (32, 64):
                rows += _rows([("normal_angle", f"bias={k} texel", "bias [texel]", float(k), 0.01, 0.02, res)])
                rows[-1].update(view=view, light="0:point", case=f"{len(rows):04d}",
                                total_texels=res * res * (6 if view == "cube" else 2))
    jobs = {a[0].name.split("_s_")[0]: (fn, a) for fn, a in figures.plot_jobs(tmp_path, rows)}
    fn, args = jobs["vs_texels"]
    fig = fn(*args)
    named = [t for ax in fig.axes for t in getattr(ax, "legend_texts", [])]
    assert sorted(named) == sorted(f"normal_angle bias={k} texel" for k in range(10))
    assert max(len(getattr(ax, "legend_texts", [])) for ax in fig.axes) <= figures.MAX_LEGEND
    assert "cube solid, dual_paraboloid dashed" in " ".join(fig._suptitle.get_text().split())   # wrapped
    assert _texts_fit(fig, figures.MIN_FONT) == (figures.MIN_FONT, [])
    # both views of every instance drawn: 10 instances x 2 views (the seam row: undefined rates, no line)
    drawn = [st for ax in fig.axes for st in _strokes(ax) if len(st[1])]
    assert len(drawn) == 10 * 2
    assert {(tuple(c), dashed) for c, _, dashed in drawn} == {
        (to_rgba(OKABE_ITO[k % 6]), dashed) for k in range(10) for dashed in (False, True)}


@pytest.mark.slow
def test_dsm_report_rebuilds_table_md_and_the_page(run, tmp_path):
    from dsm import cli
    d = tmp_path / "copy"
    shutil.copytree(run.out, d)
    want = (d / "table.md").read_text()
    plots = sorted(p.name for p in (d / "plots").glob("*.png"))
    for p in [d / "table.md", d / "report.html", *(d / "plots").glob("*.png")]:
        p.unlink()
    assert cli.main(["report", str(d)]) == 0
    assert (d / "table.md").read_text() == want
    assert sorted(p.name for p in (d / "plots").glob("*.png")) == plots and plots
    page = (d / "report.html").read_text()
    assert 'id=case-table' in page and page.count("<tr data-scene=") == len(run.rows)
    assert cli.main(["report", str(tmp_path / "nothing")]) == 2


def test_comparison_of_two_runs(run, tmp_path):
    from dsm import cli
    a = run.out
    b = tmp_path / "b"
    shutil.copytree(a, b)
    with open(b / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # B: one case has 3 more acne receivers, one case is gone
    changed, gone = rows[3], rows[5]
    old_error = float(changed["error_rate"])
    changed["n_acne"] = str(int(changed["n_acne"]) + 3)
    changed["acne_rate"] = repr(int(changed["n_acne"]) / int(changed["n_gt_lit"]))
    changed["error_rate"] = repr((int(changed["n_acne"]) + int(changed["n_peterpan"])) / int(changed["n_receivers"]))
    with open(b / "metrics.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(r for r in rows if r is not gone)
    out = tmp_path / "cmp"
    assert cli.main(["report", str(a), str(b), "--out", str(out)]) == 0
    with open(out / "compare.csv", newline="") as fh:
        cmp = list(csv.DictReader(fh))
    assert len(cmp) == len(rows) - 1 and gone["case"] not in {r["case_a"] for r in cmp}
    diff = {r["case_a"]: float(r["diff_error_rate"]) for r in cmp}
    assert diff[changed["case"]] == pytest.approx(float(changed["error_rate"]) - old_error, rel=1e-5)
    assert diff[changed["case"]] == pytest.approx(3 / int(changed["n_receivers"]), abs=1e-6)   # A's cell: 6 digits
    assert float(next(r for r in cmp if r["case_a"] == changed["case"])["a_error_rate"]) == pytest.approx(old_error)
    assert all(v == 0 for k, v in diff.items() if k != changed["case"] and not math.isnan(v))
    md = (out / "compare.md").read_text()
    assert f"{len(rows) - 1} cases in both" in md and "1 only in A, 0 only in B" in md
    # counts: every matched case but the changed one identical; its 3 receivers the largest share
    share = 100 * 3 / int(changed["n_receivers"])
    assert (f"{len(rows) - 2} of {len(rows) - 1} matched cases have identical counts; the largest difference "
            f"is {share:.3f} % of a case's receivers") in md
    # the largest change first
    first = next(line for line in md.splitlines() if line.startswith(f"| {changed['case']} |"))
    assert md.index(first) < min(md.index(f"| {r['case']} |") for r in rows if r not in (changed, gone))
    assert cli.main(["report", str(a), "--out", str(out)]) == 2


def test_a_comparison_never_lands_in_a_run_or_a_foreign_folder(run, tmp_path, capsys):
    """--out of dsm report A B: a run's folder, a file or a folder of other files is refused with
    exit 2 naming --out, and nothing in it changes; an earlier comparison is replaced."""
    from dsm import cli
    a = tmp_path / "a"
    shutil.copytree(run.out, a)
    before = sorted(p.name for p in a.iterdir())
    assert cli.main(["report", str(a), str(a), "--out", str(a)]) == 2
    assert "--out" in capsys.readouterr().err and sorted(p.name for p in a.iterdir()) == before
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    (tmp_path / "f.txt").write_text("keep")
    for out in (other, tmp_path / "f.txt"):
        assert cli.main(["report", str(a), str(a), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"dsm: report: --out {out}: ") and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"] and (tmp_path / "f.txt").read_text() == "keep"
    cmp = tmp_path / "cmp"
    assert cli.main(["report", str(a), str(a), "--out", str(cmp)]) == 0
    assert cli.main(["report", str(a), str(a), "--out", str(cmp)]) == 0       # a run with itself, again
    with open(cmp / "compare.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(run.rows) and all(r["diff_error_rate"] in ("", "0") for r in rows)


def test_the_table_of_an_interrupted_run_says_it_covers_only_the_cases_that_ran(run, tmp_path):
    """A Ctrl-C'd run's table.md (written then, or by dsm report later) must not read as the
    whole experiment's answer."""
    from dsm import cli
    assert "interrupted" not in (run.out / "table.md").read_text()
    d = tmp_path / "cut"
    shutil.copytree(run.out, d)
    info = json.loads((d / "run.json").read_text())
    info["state"] = "interrupted"
    (d / "run.json").write_text(json.dumps(info))
    with open(d / "metrics.csv", newline="") as fh:           # the first 5 cases ran
        lines = fh.read().splitlines(keepends=True)
    (d / "metrics.csv").write_text("".join(lines[:6]))
    assert cli.main(["report", str(d)]) == 0
    head = (d / "table.md").read_text().split("## Summary")[0]
    assert f"interrupted: 5 of the {len(run.rows)} planned cases ran" in head and "--resume" in head


@pytest.mark.slow
def test_dsm_report_of_a_damaged_folder_is_one_line_never_a_traceback(run, tmp_path, capsys):
    """run.json that is not JSON or not an object, a metrics.csv of another program or with text
    in a number column: exit 2 naming the file. A last row cut short (a run killed while writing
    it) and an unreadable oracle_curves.npz: the rest is reported, with a note naming the file."""
    from dsm import cli
    d = tmp_path / "d"

    def damaged(name, text):
        if d.exists():
            shutil.rmtree(d)
        shutil.copytree(run.out, d)
        (d / name).write_text(text)
        return cli.main(["report", str(d)]), capsys.readouterr().err
    metrics_text = (run.out / "metrics.csv").read_text()
    lines = metrics_text.splitlines(keepends=True)
    cells = lines[1].split(",")
    i = lines[0].split(",").index("n_acne")
    bad_cell = ",".join(cells[:i] + ["many"] + cells[i + 1:])
    for name, text in (("run.json", '{"state'), ("run.json", "[1, 2]"), ("metrics.csv", "a,b\n1,2\n"),
                       ("metrics.csv", lines[0] + bad_cell)):
        code, err = damaged(name, text)
        assert code == 2 and err.startswith(f"dsm: report: {d / name}: ") and "Traceback" not in err, err
        assert len(err.strip().splitlines()) == 1
    cut = "".join(lines[:-1]) + lines[-1][:len(lines[-1]) // 2]
    code, err = damaged("metrics.csv", cut)
    assert code == 0 and f"note: {d / 'metrics.csv'}: 1 row(s) cut short" in err
    assert f"{len(lines) - 2} cases" in (d / "table.md").read_text()
    code, err = damaged("oracle_curves.npz", "not an npz")
    assert code == 0 and f"note: {d / 'oracle_curves.npz'}: unreadable" in err and (d / "report.html").is_file()
    (tmp_path / "tuned").mkdir()
    (tmp_path / "tuned" / "tune.json").write_text("{}")
    assert cli.main(["report", str(tmp_path / "tuned")]) == 2
    assert "a dsm tune folder" in capsys.readouterr().err


@pytest.mark.slow
def test_report_images_key(tmp_path):
    import dsm
    from dsm.config import read as config
    from dsm.report import figures
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError, match=r"<t>: report\.images: unknown value 'some' \(valid: all, errors, none\)"):
        config.parse(base_config(report={"images": "some"}), "<t>")
    with pytest.raises(ConfigError, match=r"report\.image: unknown key \(did you mean 'images'\? valid: images\)"):
        config.parse(base_config(report={"image": "all"}), "<t>")
    assert config.parse(base_config(), "<t>").report_images == "all"
    small = dict(camera={"resolution": [24, 24]}, map={"resolution": 16}, scheme=[{"name": "none"}])
    for mode, want in (("all", {"_error.png", "_shadow.png"}), ("errors", {"_error.png"}), ("none", set())):
        res = dsm.run(base_config(report={"images": mode}, **small), out=tmp_path / mode)
        files = sorted(p.relative_to(res.out).as_posix() for p in (res.out / "images").rglob("*.png"))
        err, shadow = figures.image_paths(res.rows[0])
        display = list(figures.display_paths(res.rows[0])) if mode == "all" else []    # the scene's display renders
        assert files == sorted([p for p, s in ((err, "_error.png"), (shadow, "_shadow.png")) if s in want] + display), mode
        assert err == f"images/plane_0_directional/{res.rows[0]['case']}_error.png"
    # the shadow image is the render: lit receivers brighter than the ambient 0.12 floor
    from PIL import Image
    grey = np.asarray(Image.open(tmp_path / "all" / figures.image_paths(res.rows[0])[1]))
    assert grey.max() > round(0.12 * 255)


def test_images_sit_in_one_folder_per_scene_and_light(run):
    from dsm.report import figures
    folders = {p.name for p in (run.out / "images").iterdir()}
    assert folders == {figures.image_folder(r) for r in run.rows} and len(folders) == 2
    for r in run.rows:
        for p in figures.image_paths(r):
            assert (run.out / p).is_file()


def _unlike_in_a_fork(parent_pid: int, path, how: str):
    """Writes ``path`` in the parent; in a forked child fails (``how`` "raise") or never returns ("hang")."""
    if os.getpid() != parent_pid:
        if how == "hang":
            time.sleep(3600)
        raise RuntimeError("only the parent can draw this")
    path.write_text("drawn")


@pytest.mark.parametrize("how", ["raise", "hang"])
def test_a_forked_share_that_fails_or_hangs_is_drawn_here(tmp_path, monkeypatch, capsys, how):
    from dsm.report import jobs as draw_jobs
    if not hasattr(os, "fork"):
        pytest.skip("no os.fork on this platform")
    monkeypatch.setattr(draw_jobs, "HANG_S", 1.0)
    monkeypatch.setattr(draw_jobs, "workers", lambda: 2)
    jobs = [(_unlike_in_a_fork, (os.getpid(), tmp_path / f"{i}.txt", how)) for i in range(2)]
    assert draw_jobs.run_jobs(jobs, pool_min=1, fork=True) == 2
    assert [(tmp_path / f"{i}.txt").read_text() for i in range(2)] == ["drawn", "drawn"]
    why = "RuntimeError: only the parent can draw this" if how == "raise" else "no answer 1 s after"
    assert f"a drawing worker failed ({why}" in capsys.readouterr().err


KILLED_PARENT = """
import os, sys, time
from pathlib import Path
from dsm.report import jobs
def job(folder, who):
    Path(folder, who + ".pid").write_text(str(os.getpid()))
    time.sleep(3600)
jobs.workers = lambda: 2
# shares dealt interleaved: this process draws jobs 0 and 2 (the first before it forks), the fork job 1
jobs.run_jobs([(print, ()), (job, (sys.argv[1], "child")), (job, (sys.argv[1], "parent"))], pool_min=1, fork=True)
"""


def test_a_forked_drawing_worker_dies_with_its_parent(tmp_path):
    """kill -9 of the run while a fork draws: the fork must not live on (it holds the run folder's
    lock and would keep writing into it)."""
    import signal
    import subprocess
    import sys
    if not sys.platform.startswith("linux"):
        pytest.skip("forked workers are Linux's")
    p = subprocess.Popen([sys.executable, "-c", KILLED_PARENT, str(tmp_path)])
    pids = [tmp_path / "parent.pid", tmp_path / "child.pid"]
    deadline = time.monotonic() + 60
    while not all(f.is_file() and f.read_text() for f in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    child = int(pids[1].read_text())
    try:
        assert int(pids[0].read_text()) == p.pid != child
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        state = lambda: (Path(f"/proc/{child}/stat").read_text().split(")")[-1].split()[0]
                         if Path(f"/proc/{child}").exists() else "gone")
        deadline = time.monotonic() + 10
        while state() not in ("Z", "X", "gone") and time.monotonic() < deadline:
            time.sleep(0.05)
        assert state() in ("Z", "X", "gone")     # killed (a zombie until its new parent reaps it)
    finally:
        for pid in (p.pid, child):               # a failed test leaves no sleeper behind
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


@pytest.mark.slow
@pytest.mark.parametrize("fork", [True, False])
def test_drawing_in_a_process_pool_writes_what_drawing_here_writes(tmp_path, fork):
    from dsm.report import figures, jobs as draw_jobs
    from dsm.truth import metrics
    if fork and not hasattr(os, "fork"):
        pytest.skip("no os.fork on this platform: the started workers serve")
    rng = np.random.default_rng(3)
    items = [(f"images/a/{i}_error.png", rng.integers(0, len(metrics.CLASS_COLORS), (8, 9)).astype(np.uint8),
              f"images/a/{i}_shadow.png", rng.integers(0, 256, (8, 9)).astype(np.uint8)) for i in range(4)]
    jobs = [(figures.write_images, (tmp_path / "pool", items[:2])), (figures.write_images, (tmp_path / "pool", items[2:]))]
    assert draw_jobs.run_jobs(jobs, pool_min=1, fork=fork) == (2 if draw_jobs.workers() >= 2 else 0)
    draw_jobs.run_jobs([(figures.write_images, (tmp_path / "here", items))], pool_min=10)
    from PIL import Image
    for err, classes, shadow, grey in items:
        for base in ("pool", "here"):
            assert (np.asarray(Image.open(tmp_path / base / err).convert("RGB")) == metrics.CLASS_COLORS[classes]).all()
            assert (np.asarray(Image.open(tmp_path / base / shadow)) == grey).all()
