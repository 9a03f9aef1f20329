"""dsm.run (dsm/pipeline.py) under the command line's folder rules: a previous run kept unless told, --force
clearing only what a run wrote."""
import tomllib

import pytest

import dsm
from conftest import metrics_rows, tiny_toml, write_cfg
from dsm import cli
from dsm.config.read import ConfigError


@pytest.mark.slow
def test_the_api_keeps_a_previous_run_unless_told(tmp_path):
    a = tomllib.loads(tiny_toml())
    b = tomllib.loads(tiny_toml().replace('name = "none"', 'name = "constant"'))
    out = tmp_path / "o"
    dsm.run(a, out=out, report=False)
    before = (out / "metrics.csv").read_bytes()
    with pytest.raises(ConfigError) as e:
        dsm.run(b, out=out, report=False)
    assert e.value.key == "out" and "resume=True" in str(e.value) and "force=True" in str(e.value)
    assert (out / "metrics.csv").read_bytes() == before
    assert [r["scheme"] for r in metrics_rows(out)] == ["none"]
    res = dsm.run(a, out=out, resume=True, report=False)
    assert res.run["resumed_cases"] == 1
    dsm.run(b, out=out, force=True, report=False)
    assert [r["scheme"] for r in metrics_rows(out)] == ["constant"]
    other = tomllib.loads(tiny_toml(name="other"))
    with pytest.raises(ConfigError) as e:
        dsm.run(other, out=out, resume=True, report=False)
    assert "holds experiment 't'" in str(e.value)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "keep.txt").write_text("mine")
    with pytest.raises(ConfigError):
        dsm.run(a, out=tmp_path / "mine", force=True, report=False)
    assert [p.name for p in (tmp_path / "mine").iterdir()] == ["keep.txt"]


@pytest.mark.slow
def test_force_clears_only_what_a_run_wrote_inside_images_and_plots(tmp_path):
    """A user's files inside a run's images/ and plots/ survive --force; the run's own are
    replaced (issue: --force deleted plots/keep.txt, images/mine.txt, images/album/)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": [16, 32]},
                      scheme=[{"name": "constant"}])
    out = tmp_path / "r"
    dsm.run(raw, out=out)
    (out / "plots" / "keep.txt").write_text("mine")
    (out / "images" / "mine.txt").write_text("mine")
    (out / "images" / "album").mkdir()
    (out / "images" / "album" / "photo.jpg").write_bytes(b"jpg")
    old = sorted(p.name for p in (out / "images").rglob("*_error.png"))
    stale = out / "images" / "plane_box_0_directional" / "0099_error.png"     # a dsm image of no current case
    stale.write_bytes(b"x")
    # a display render and a figure's case points of a scene and view the new run does not have
    (out / "images" / "gone_0_directional").mkdir()
    stale_display = out / "images" / "gone_0_directional" / "display_nl.png"
    stale_points = out / "plots" / "pareto_gone.points.json"
    stale_display.write_bytes(b"x")
    stale_points.write_text("[]")
    assert cli.main(["run", str(write_cfg(tmp_path, raw)), "--out", str(out), "--force"]) == 0
    assert not stale_display.exists() and not stale_display.parent.exists() and not stale_points.exists()
    assert (out / "images" / "plane_box_0_directional" / "display_nl.png").is_file()
    assert (out / "plots" / "keep.txt").read_text() == "mine" and (out / "images" / "mine.txt").read_text() == "mine"
    assert (out / "images" / "album" / "photo.jpg").read_bytes() == b"jpg"
    assert not stale.exists() and sorted(p.name for p in (out / "images").rglob("*_error.png")) == old
