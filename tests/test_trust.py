"""Numbers a user can trust: a scheme's counts do not depend on what else runs."""
import pytest

from conftest import base_config

ONE_LAYER = [{"name": "none"}, {"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"},
             {"name": "normal_angle"}, {"name": "normal_offset"}, {"name": "receiver_plane"}, {"name": "adaptive"}]
LAYERED = [{"name": "midpoint", "culling": "none"}, {"name": "dual", "culling": "back_closed"},
           {"name": "second_depth"}, {"name": "midpoint", "culling": "back"}]
LIGHTS = [{"type": "directional", "direction": [-0.3, -0.2, -1.0]},
          {"type": "spot", "position": [-2.0, 1.5, 4.0], "target": [0.0, 0.0, 0.0], "cutoff": 45},
          {"type": "point", "position": [0.3, -0.2, 2.5]}]


@pytest.mark.parametrize("scene", ["plane_box", "l_shape", "room"])
def test_counts_do_not_depend_on_the_other_schemes(run_dict, scene):
    """Each scheme alone against the same scheme beside layered and culled schemes, on all five
    views: n_receivers, n_acne and n_peterpan are identical."""
    common = dict(scene=[{"builtin": scene}], light=LIGHTS, camera={"resolution": [64, 64]},
                  map={"resolution": 128, "view": ["paraboloid", "dual_paraboloid", "cube"]})
    together = run_dict(base_config(scheme=ONE_LAYER + LAYERED, **common), "together")
    views = {r["view"] for r in together.rows}
    assert views == {"orthographic", "perspective", "paraboloid", "dual_paraboloid", "cube"}
    key = lambda r: (r["light"], r["view"], r["scheme"], r["params"])
    both = {key(r): r for r in together.rows}
    # the one-layer schemes without any layered or culled map, and midpoint without culling
    for i, group in enumerate((ONE_LAYER, LAYERED[:1])):
        alone = run_dict(base_config(scheme=group, **common), f"alone{i}")
        assert len(alone.rows) == 5 * len(group)
        for r in alone.rows:
            other = both[key(r)]
            for col in ("n_receivers", "n_acne", "n_peterpan"):
                assert r[col] == other[col], (r["scheme"], r["view"], col, r[col], other[col])
    assert sum(r["n_receivers"] for r in together.rows) > 0


def test_inward_wound_room_is_not_culled(run_dict):
    """A spot above the closed room (wound inward): back_closed culling must not let the light
    through the ceiling, so dual with back_closed equals dual without culling, and every
    receiver inside is truly shadowed (the room is closed, the light outside)."""
    cfg = base_config(scene=[{"builtin": "room"}], camera={"resolution": [64, 64]}, map={"resolution": 128},
                      light=[{"type": "spot", "position": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "cutoff": 40}],
                      scheme=[{"name": "dual", "culling": ["none", "back_closed"]}])
    res = run_dict(cfg)
    a, b = res.rows
    assert a["n_receivers"] > 500 and a["n_gt_lit"] == 0 == b["n_gt_lit"]
    assert a["n_peterpan"] == b["n_peterpan"] == 0
    room = next(s for sc in res.run["scenes"] for s in sc["shapes"] if s["name"] == "room")
    assert room["closed"] is False and "inward" in room["why"]
