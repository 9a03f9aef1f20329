"""Light inputs (dsm/lights): directions beyond float32 measured as their direction in float64, an emitter
light on a scene without one and lights' scenes that name no scene refused in one line."""
import tomllib

import pytest

import dsm
from conftest import tiny_toml, cli_run as _cli, one_line as _one_line, base_config, toml_text
from dsm.config import read as config, plan


@pytest.mark.slow
def test_a_light_direction_beyond_float32_gives_the_counts_of_its_direction(tmp_path):
    """Each hostile direction beside the plain one it points along, on plane_box: same counts."""
    pairs = [([1e-300, 0, -1e-300], [1, 0, -1]), ([1e308, 1e308, -1e308], [1, 1, -1]),
             ([0, 0, -1e-320], [0, 0, -1])]
    lights = "".join(f'[[light]]\ntype = "directional"\ndirection = [{", ".join(map(repr, map(float, d)))}]\n'
                     for pair in pairs for d in pair)
    cfg = tomllib.loads(tiny_toml(lights, 'builtin = "plane_box"'))
    rows = dsm.run(cfg, out=tmp_path / "o", report=False).rows
    assert len(rows) == 6
    keys = ("n_receivers", "n_gt_lit", "n_gt_shadowed", "n_acne", "n_peterpan", "n_excluded_backfacing")
    for i in range(3):
        hostile, plain = rows[2 * i], rows[2 * i + 1]
        assert plain["n_receivers"] > 0                    # the case was empty, every pixel "backfacing"
        assert {k: hostile[k] for k in keys} == {k: plain[k] for k in keys}, pairs[i]
    assert sum(r["n_gt_shadowed"] for r in rows) > 0      # the box casts a shadow under some of them


def test_a_light_direction_is_a_float64_unit_vector():
    raw = tomllib.loads(tiny_toml('[[light]]\ntype = "directional"\ndirection = [1e-300, 0, -1e-300]\n'))
    (light,) = config.parse(raw).lights
    assert light.direction == pytest.approx((2 ** -0.5, 0.0, -(2 ** -0.5)), rel=1e-15, abs=0)


def test_an_emitter_light_on_a_scene_without_one_is_refused_naming_it(tmp_path, capsys):
    from dsm import cli
    cfg = tmp_path / "e.toml"
    cfg.write_text('[experiment]\nname = "e"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   '[[light]]\ntype = "area"\nshape = "emitter"\n[map]\nresolution = 32\n[[scheme]]\nname = "none"\n')
    for cmd in (["plan", str(cfg)], ["run", str(cfg), "--out", str(tmp_path / "o")]):
        capsys.readouterr()
        assert cli.main(cmd) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "light[0].shape" in err[0] and "plane_box" in err[0] and "no area emitter" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_lights_scenes_that_name_no_scene_are_a_config_error(tmp_path, capsys):
    """scenes = ["plane"] beside only plane_box lit nothing: a run of 0 cases, exit 0."""
    light = {"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}
    scene = [{"builtin": "plane_box", "precision": ["world", "camera_relative"]}]
    path = tmp_path / "c.toml"
    path.write_text(toml_text(base_config(scene=scene, light=[{**light, "scenes": ["plane"]}])))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "light[0].scenes", "'plane'", "plane_box(precision=camera_relative)")
    for names, lit in ((["plane_box"], 2), (["plane_box(precision=camera_relative)"], 1)):   # a first word; a label
        p = plan.make(config.parse(base_config(scene=scene, light=[{**light, "scenes": names}]), "<test>"))
        assert sum(1 for _, _, _, lights in p.scenes if lights) == lit
