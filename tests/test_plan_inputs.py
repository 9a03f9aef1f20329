"""The plan (dsm/config/plan.py): a scheme that no map reads is a config error, not a dropped case; a voxel
view and a spot light plan both."""

import pytest

from conftest import cli_run as _cli, one_line as _one_line, base_config, toml_text
from dsm.config import read as config, plan


@pytest.mark.parametrize("light,views,schemes,words", [
    # a point light given only a voxel grid: the depth scheme was dropped without a case
    ({"type": "point", "position": [0.6, -0.8, 2.2]}, ["vsv"], [{"name": "vsv"}, {"name": "constant"}],
     ["constant", "depth view"]),
    # a sphere area light gets the point views but a VSV grid: 0 cases, exit 0
    ({"type": "area", "shape": "sphere", "position": [0.6, -0.4, 3.0], "size": 0.5}, ["vsv"], [{"name": "vsv"}],
     ["vsv", "point and spot"]),
    ({"type": "area", "shape": "sphere", "position": [0.6, -0.4, 3.0], "size": 0.5}, ["vsv", "cube"],
     [{"name": "vsv_adaptive"}, {"name": "constant"}], ["vsv_adaptive", "cube"]),
])
def test_a_scheme_no_map_reads_is_a_config_error_not_a_dropped_case(tmp_path, capsys, light, views, schemes, words):
    cfg = base_config(scene=[{"builtin": "plane_box"}], light=[light], map={"resolution": 64, "view": views},
                      scheme=schemes)
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "map.view", *words)


def test_vsv_beside_a_spot_light_still_plans_both():
    """The spot light gets its perspective map and a VSV grid: both schemes are read."""
    cfg = config.parse(base_config(scene=[{"builtin": "plane_box"}], map={"resolution": 64, "view": ["vsv"]},
                                   light=[{"type": "spot", "position": [-2.0, 2.5, 2.6], "target": [0, 0, 0],
                                           "cutoff": 40}], scheme=[{"name": "vsv"}, {"name": "constant"}]), "<test>")
    assert sorted((m.view, m.cases) for m in plan.make(cfg).maps) == [("perspective", 1), ("vsv", 1)]


def test_a_vsv_view_for_a_directional_light_names_spot_lights_too(tmp_path, capsys):
    cfg = base_config(light=[{"type": "directional", "direction": [0.2, 0.1, -1.0]}],
                      map={"resolution": 64, "view": "vsv"}, scheme=[{"name": "vsv"}])
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, "map.view", "point light", "spot light")
