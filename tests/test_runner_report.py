"""A run without its report (dsm run --no-report, dsm.run(report=False)): the same measurements, no figures, and
``dsm report`` draws the report from the folder afterwards."""
import pytest

import dsm
from conftest import base_config, cli_lines, metrics_rows

# the columns that depend on the machine or the clock, not on what was measured
MACHINE = ("_ms", "_s", "peak", "cpu", "kernel", "launch")


def _config():
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": 32},
                       scheme=[{"name": "constant"}, {"name": "slope_scaled"}])


def _measured(rows: list) -> list:
    return [{k: v for k, v in r.items() if not any(m in k for m in MACHINE)} for r in rows]


@pytest.fixture(scope="module")
def with_report(tmp_path_factory):
    """The config run with its report, once for this file's tests (each compares a run without it to it)."""
    return dsm.run(_config(), out=tmp_path_factory.mktemp("with_report") / "a")


def test_no_report_measures_the_same_rows_and_draws_nothing(with_report, tmp_path):
    without = dsm.run(_config(), out=tmp_path / "b", report=False)
    assert _measured(metrics_rows(tmp_path / "b")) == _measured(metrics_rows(with_report.out))
    assert len(without.rows) == len(with_report.rows) == 2
    for name in ("report.html", "table.md", "plots", "frontier.csv"):
        assert (with_report.out / name).exists() and not (tmp_path / "b" / name).exists(), name
    notes = [s for s in without.run["status"] if s["what"] == "report"]
    assert len(notes) == 1 and "dsm report" in notes[0]["error"]


def test_dsm_report_draws_a_no_report_run_afterwards(with_report, tmp_path, capsys):
    rc, _ = cli_lines(capsys, "run", str(_write(tmp_path)), "--out", tmp_path / "b", "--no-report")
    assert rc == 0 and not (tmp_path / "b" / "report.html").exists()
    rc, _ = cli_lines(capsys, "report", tmp_path / "b")
    assert rc == 0 and (tmp_path / "b" / "report.html").is_file()
    # the answer table.md opens with (words and rates: no time in it)
    table = lambda d: [line for line in (d / "table.md").read_text().splitlines() if line.startswith("**Lowest")]
    assert table(tmp_path / "b") == table(with_report.out) != []


def _write(tmp_path):
    from conftest import write_cfg
    return write_cfg(tmp_path, _config())
