"""The run record (dsm.core.record) and the one report composer (dsm.report.publish): a row that does not fit
metrics.csv's schema is refused, and `dsm report DIR` rebuilds exactly what `dsm run` wrote."""
import csv
import json
import shutil

import numpy as np
import pytest

from conftest import base_config

# what a run's report is composed from; everything else in the folder is the report
DATA = {"metrics.csv", "oracle.csv", "oracle_curves.npz", "cascades.csv", "cascade_curves.csv", "frames.csv",
        "run.json", "images"}


def _row(**over):
    from dsm.core import record
    row = {c: ("x" if c in record.TEXT_COLUMNS else 1) for c in record.GROUPS["core"]}
    row.update(over)
    return row


def test_a_row_must_fit_the_schema(tmp_path):
    from dsm.core import record
    from dsm.report import io as report
    w = report.CsvWriter(tmp_path / "metrics.csv")
    w.write(_row(case="0001"))                                   # core columns alone: a row
    with pytest.raises(record.SchemaError, match="flicker_rat"):
        w.write(_row(flicker_rat=0.1))                           # a typo would have vanished
    with pytest.raises(record.SchemaError, match="motion columns lack.*flicker_ever"):
        w.write(_row(**{k: 1 for k in record.GROUPS["motion"] - {"flicker_ever"}}))
    core = _row()
    del core["n_acne"]
    with pytest.raises(record.SchemaError, match="core columns lack n_acne"):
        w.write(core)
    rows = list(csv.DictReader(open(tmp_path / "metrics.csv")))
    assert [r["case"] for r in rows] == ["0001"] and list(rows[0]) == record.NAMES


def test_every_row_a_run_writes_fits_and_the_groups_are_the_kinds_of_case(run_dict):
    from dsm.core import record
    res = run_dict(base_config(scene=[{"builtin": "plane_box"}], map={"resolution": 32},
                               scheme=[{"name": "constant"}, {"name": "dual"}]))
    for r in res.rows:
        assert record.check_row(r) is r
        assert set(r) == (record.GROUPS["core"] | record.GROUPS["map"] | record.GROUPS["precision"]
                          | record.GROUPS["cost"])


def _cascaded():
    return base_config(scene=[{"builtin": "long_ground"}], camera={"resolution": [48, 48]},
                       map={"resolution": 32, "cascades": 3}, scheme=[{"name": "constant", "bias": "1 texel"}])


def _motion():
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                       light=[{"type": "spot", "position": [1.0, -1.0, 3.0], "target": [0.0, 0.0, 0.0]}],
                       map={"resolution": 32}, motion=[{"frames": 3, "light": "move", "light_offset": [0.3, 0, 0],
                                                        "points": 300}])


def _area():
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                       light=[{"type": "area", "shape": "rectangle", "position": [0.5, -0.5, 3.0],
                               "direction": [0.0, 0.0, -1.0], "size": 0.5, "max_samples": 64}],
                       map={"resolution": 32, "filter": ["nearest", "pcss"]}, scheme=[{"name": "constant"}])


@pytest.mark.parametrize("make", [_cascaded, pytest.param(_motion, marks=pytest.mark.slow),
                                  pytest.param(_area, marks=pytest.mark.slow)], ids=["cascades", "motion", "area"])
def test_dsm_report_rebuilds_what_dsm_run_wrote(tmp_path, make):
    """Every file but the run's data deleted, `dsm report` gives back the text files byte for byte
    and the figures pixel for pixel (cascades.md and the cascade and flicker plots included)."""
    from PIL import Image

    import dsm
    from dsm import cli
    run = tmp_path / "run"
    res = dsm.run(make(), out=run)
    assert res.run["n_failed"] == 0 and res.rows
    kinds = {"cascades": "cascades.md", "motion": "frames.csv", "area": "oracle.csv"}
    again = tmp_path / "again"
    shutil.copytree(run, again)
    for p in again.iterdir():
        if p.name not in DATA:
            shutil.rmtree(p) if p.is_dir() else p.unlink()
    assert cli.main(["report", str(again)]) == 0
    files = lambda d: sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())
    assert files(again) == files(run)
    assert any(kinds[k] in files(run) for k in kinds)
    plots = [f for f in files(run) if f.startswith("plots/")]
    assert plots and (make is not _cascaded or any("cascades_" in f for f in plots))
    assert make is not _motion or any("flicker_" in f for f in plots)
    for f in files(run):
        a, b = run / f, again / f
        if f.endswith(".png"):
            assert np.array_equal(np.asarray(Image.open(a)), np.asarray(Image.open(b))), f
        else:
            assert a.read_bytes() == b.read_bytes(), f
    assert json.loads((again / "run.json").read_text())["state"] == "complete"


def test_merge_folds_a_tasks_record_once_per_scene_and_light():
    """Two Ray tasks of one scene and light: rows and cases from both (tagged with their node),
    the scene's note, G-buffer and reference rays once, every map's own rays, the area light's
    reference regions (which the hand packing of old dropped)."""
    from dsm.core.record import RunRecord
    driver, seen = RunRecord(), set()
    for i in range(2):
        task = RunRecord(rows=[{"case": f"000{i}"}], status=[{"what": f"case 000{i}", "status": "ok"},
                                                             {"what": "scene s", "status": "note", "error": "n"}],
                         maps=[{"scene": "s"}], gbuffer_ms={"s": 1.0 + i},
                         rays={"gbuffer": 100, "reference": 40, "map_texel": 16, "map_continue": 2},
                         reference_regions=[{"scene": "s", "light": "0:area", "umbra": 3}])
        driver.merge(task, f"node{i}", 10 + i, seen, "s", ("s", "0:area"))
    assert [r["case"] for r in driver.rows] == ["0000", "0001"]
    cases = [s for s in driver.status if s["what"].startswith("case")]
    assert [(s["node"], s["worker"]) for s in cases] == [("node0", 10), ("node1", 11)]
    assert sum(s["status"] == "note" for s in driver.status) == 1
    assert driver.rays == {"gbuffer": 100, "reference": 40, "map_texel": 32, "map_continue": 4}
    assert driver.gbuffer_ms == {"s": 1.0} and [m["node"] for m in driver.maps] == ["node0", "node1"]
    assert driver.reference_regions == [{"scene": "s", "light": "0:area", "umbra": 3}]
