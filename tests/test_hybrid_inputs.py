"""[hybrid] (dsm/hybrid): an instance given by two tables is refused; the plan's ray count bounds the rays a
run casts."""
import csv

import pytest

from conftest import base_config, cli_run, one_line, folder_files, write_toml


def test_an_instance_given_by_two_hybrid_tables_is_refused(tmp_path, capsys):
    tables = [{"rule": "band", "k": [0.1, 1.0]}, {"rule": "band", "k": [1.0, 3.0]}]
    cfg = write_toml(tmp_path / "h.toml", base_config(camera={"resolution": [32, 32]}, map={"resolution": 32},
                                                 hybrid=tables))
    before = folder_files(tmp_path)
    rc, err = cli_run(capsys, "run", cfg, "--out", tmp_path / "out")
    assert rc == 2
    one_line(err, str(cfg), "hybrid[1]", "band k=1.0 from spawn is already hybrid[0]'s", "give each instance once")
    assert folder_files(tmp_path) == before and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_plan_bounds_the_hybrid_rays_the_run_casts(tmp_path):
    """rule all from two origins: a ray per receiver per origin. The plan's bound is the camera's pixels
    per hybrid case; run.json's count is the sum of the rows' hybrid_rays, each its case's receivers."""
    import dsm
    from dsm.config import plan, read
    raw = base_config(camera={"resolution": [32, 24]}, scene=[{"builtin": "plane_box"}], map={"resolution": 32},
                      scheme=[{"name": "constant", "bias": "1 texel"}], report={"images": "none"},
                      hybrid={"rule": "all", "origin": ["spawn", "epsilon"]})
    p = plan.make(read.parse(raw, "<t>"))
    assert p.rays_bound["hybrid"] == 2 * 32 * 24
    assert "hybrid" not in plan.make(read.parse({k: v for k, v in raw.items() if k != "hybrid"}, "<t>")).rays_bound
    res = dsm.run(raw, out=tmp_path / "out", report=False)
    rows = list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))
    assert [int(r["hybrid_rays"]) for r in rows] == [int(r["n_receivers"]) for r in rows] and len(rows) == 2
    assert res.run["rays"]["hybrid"] == sum(int(r["n_receivers"]) for r in rows) <= p.rays_bound["hybrid"]
