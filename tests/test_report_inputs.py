"""dsm report's inputs (dsm/report): a metrics.csv without a core column, with rates not its counts or an
edited cost column refused in one line; a damaged folder's missing files named; a rebuilt frontier is the
one its counts give."""
import csv
import json
import math
import numpy as np
import shutil

import pytest

from conftest import small_run, base_config, cli_run, one_line, folder_files
from dsm import cli


@pytest.mark.slow
def test_report_refuses_a_metrics_csv_without_a_core_column_or_with_rates_not_its_counts(tmp_path, capsys):
    import csv as csvmod
    from dsm import cli
    res = small_run(tmp_path)
    path = res.out / "metrics.csv"
    rows = list(csvmod.DictReader(open(path)))
    header = list(rows[0])

    def write(rows, header):
        with open(path, "w", newline="") as fh:
            w = csvmod.DictWriter(fh, header, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    write(rows, [h for h in header if h != "n_receivers"])
    capsys.readouterr()
    assert cli.main(["report", str(res.out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "n_receivers" in err[0] and "Traceback" not in err[0]
    edited = [dict(r) for r in rows]
    edited[0]["acne_rate"] = "7.5"
    write(edited, header)
    assert cli.main(["report", str(res.out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "acne_rate 7.5" in err[0] and "n_acne / n_gt_lit" in err[0]
    write(rows, header)                                              # the file as the run wrote it
    assert cli.main(["report", str(res.out)]) == 0


@pytest.mark.slow
def test_report_says_what_a_damaged_folder_lacks(tmp_path, capsys):
    """A duplicated row is refused; rows lost against run.json, or oracle.csv deleted, are notes
    (the report was silently shorter); run.json's config as a string is no traceback."""
    res = small_run(tmp_path)
    lines = (res.out / "metrics.csv").read_text().splitlines()
    (res.out / "metrics.csv").write_text("\n".join(lines + [lines[1]]) + "\n")
    capsys.readouterr()
    assert cli.main(["report", str(res.out)]) == 2
    assert "appears twice" in capsys.readouterr().err
    (res.out / "metrics.csv").write_text(lines[0] + "\n")            # the header alone
    (res.out / "oracle.csv").unlink()
    assert cli.main(["report", str(res.out)]) == 0
    err = capsys.readouterr().err
    assert "1 case(s) run.json lists as finished have no row" in err
    (res.out / "metrics.csv").write_text("\n".join(lines) + "\n")
    assert cli.main(["report", str(res.out)]) == 0
    assert "oracle.csv is absent" in capsys.readouterr().err
    run = json.loads((res.out / "run.json").read_text())
    (res.out / "run.json").write_text(json.dumps({**run, "config": "not a table"}))
    assert cli.main(["report", str(res.out)]) == 0


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A run of two schemes at two map sizes on one scene: six cases, a frontier of several points."""
    import dsm
    out = tmp_path_factory.mktemp("tour") / "run"
    dsm.run(base_config(camera={"resolution": [32, 32]}, scene=[{"builtin": "plane_box"}],
                        map={"resolution": [32, 64]},
                        scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"}, {"name": "none"}],
                        report={"images": "none"}), out=out)
    return out


def _edit_cell(col, value):
    def f(path):
        rows = list(csv.reader(open(path, newline="")))
        rows[1][rows[0].index(col)] = value
        csv.writer(open(path, "w", newline="")).writerows(rows)
    return f


def _drop_column(col):
    def f(path):
        rows = list(csv.reader(open(path, newline="")))
        i = rows[0].index(col)
        csv.writer(open(path, "w", newline="")).writerows([r[:i] + r[i + 1:] for r in rows])
    return f


EDITED = {  # metrics.csv as the tour edited it -> words of the one line
    "map_bytes = -5 (exit 0, on the frontier)": (_edit_cell("map_bytes", "-5"),
                                                 ["case 0001: map_bytes -5 is not a count"]),
    "map_bytes empty (a traceback)": (_edit_cell("map_bytes", ""), ["case 0001: map_bytes nan is not a count"]),
    "taps = -1 (exit 0)": (_edit_cell("taps", "-1"), ["case 0001: taps -1.0", "a number >= 0"]),
    "page_table_bytes = -1 (exit 0)": (_edit_cell("page_table_bytes", "-1"), ["page_table_bytes -1 is not a count"]),
    "no map_bytes column (exit 0, no frontier)": (_drop_column("map_bytes"), ["no map_bytes column", "map_rays"]),
    "no map_rays column (a KeyError)": (_drop_column("map_rays"), ["no map_rays column", "map_bytes"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(EDITED))
def test_report_refuses_an_edited_cost_column(name, tiny_run, tmp_path, capsys):
    edit, words = EDITED[name]
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    edit(run / "metrics.csv")
    before = folder_files(run)
    rc, err = cli_run(capsys, "report", run)
    assert rc == 2
    one_line(err, str(run / "metrics.csv"), "an edited file", *words)
    assert folder_files(run) == before


def _frontier_float64(metrics_csv) -> list:
    """on_frontier of each row as the design defines it, computed here in float64 from the counts: no
    other point has error, bytes and rays each at most its own and one lower; undefined error: ''."""
    rows = list(csv.DictReader(open(metrics_csv)))
    pts = np.array([[(float(r["n_acne"]) + float(r["n_peterpan"])) / float(r["n_receivers"])
                     if float(r["n_receivers"]) else math.nan,
                     float(r["map_bytes"]) + float(r["page_table_bytes"]), float(r["map_rays"])] for r in rows])
    out = []
    for p in pts:
        others = pts[~np.isnan(pts[:, 0])]
        beaten = np.any(np.all(others <= p, axis=1) & np.any(others < p, axis=1))
        out.append("" if math.isnan(p[0]) else ("0" if beaten else "1"))
    return out


def test_a_rebuilt_frontier_is_the_one_its_counts_give_and_none_without_rows(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / "frontier.csv").write_text("scene,on_frontier\nforged,1\n")
    rc, _ = cli_run(capsys, "report", run)
    assert rc == 0
    got = [r["on_frontier"] for r in csv.DictReader(open(run / "frontier.csv"))]
    assert got == _frontier_float64(run / "metrics.csv") and "1" in got and "0" in got
    header = (run / "metrics.csv").read_text().splitlines()[0]
    (run / "metrics.csv").write_text(header + "\n")          # every row gone: no frontier of rows not there
    rc, err = cli_run(capsys, "report", run)
    assert rc == 0 and any("have no row" in line for line in err)
    assert not (run / "frontier.csv").exists()
    assert {"run.json", "metrics.csv", "report.html", "table.md"} <= set(folder_files(run))
