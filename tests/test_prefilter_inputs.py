"""Pre-filtered map kinds (dsm/prefilter) without a scheme beside them: planned and measured as beside one;
beside only a voxel grid a config error."""

import pytest

from conftest import base_config
from dsm.config import read as config, plan
from dsm.config.read import ConfigError


def _point_light_cfg(views, kinds, schemes):
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                       light=[{"type": "point", "position": [0.6, -0.8, 2.2]}],
                       map={"resolution": 64, "view": views, "kind": kinds}, scheme=schemes)


@pytest.mark.slow
def test_pre_filtered_kinds_without_any_scheme_are_planned_and_measured_as_beside_one(run_dict):
    """The error for [[scheme]] tables without depth in map.kind says "or remove them": doing so
    planned no case at all (exit 0, an empty run). Now the kinds are measured, and each row is the
    one the same kind gets beside a depth scheme (a case never depends on the others)."""
    alone = base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [48, 48]},
                        map={"resolution": 64, "kind": ["vsm", "esm"], "blur": [1, 3]})
    del alone["scheme"]
    p = plan.make(config.parse(alone, "<test>"))
    assert p.cases == 2 * 2                       # 2 kinds x 2 blurs x 1 format, on the one directional map
    with_depth = {**alone, "map": {**alone["map"], "kind": ["depth", "vsm", "esm"]},
                  "scheme": [{"name": "constant"}]}
    a, b = run_dict(alone, "alone").rows, run_dict(with_depth, "beside").rows
    assert [r["scheme"] for r in a] == ["vsm", "vsm", "esm", "esm"]
    moments_b = [r for r in b if r["map_kind"] != "depth"]
    assert len(moments_b) == 4
    for ra, rb in zip(a, moments_b):
        for k in ("scheme", "filter", "n_receivers", "n_gt_shadowed", "n_acne", "n_peterpan", "n_leak",
                  "mean_abs_error"):
            assert ra[k] == rb[k], (k, ra[k], rb[k])


def test_a_voxel_grid_gets_no_moment_map():
    """A VSV grid's depth is a fraction of its alpha range, not a depth: VSM over it measured a
    meaningless case. The kinds go on the depth views only."""
    cfg = config.parse(_point_light_cfg(["cube", "vsv"], ["depth", "vsm"],
                                        [{"name": "constant"}, {"name": "vsv_adaptive"}]), "<test>")
    p = plan.make(cfg)
    assert [(m.view, len(m.moments)) for m in p.maps] == [("cube", 1), ("vsv", 0)]
    assert p.cases == 1 + 1 + 1                   # constant, vsm on the cube; vsv_adaptive on the grid


def test_pre_filtered_kinds_with_only_a_voxel_grid_are_a_config_error(capsys, tmp_path):
    cfg = config.parse(_point_light_cfg(["vsv"], ["depth", "vsm"], [{"name": "vsv_adaptive"}]), "<test>")
    with pytest.raises(ConfigError) as e:
        plan.make(cfg)
    assert e.value.key == "map.kind" and "cube" in str(e.value)
