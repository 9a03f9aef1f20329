"""dsm grad's inputs and undefined answers (dsm/grad): what it would ignore or measure in another scene is
refused; a relative error against a zero truth is undefined, not a number."""

import math
import tomllib

import pytest

from conftest import cli_lines, one_line
from dsm.core.types import ConfigError
from dsm.grad import spec as specmod
from helpers_grad import config, toml


def _toml(light, param, extra):
    return toml(config(light=light, map_resolution=32, image_resolution=32, params=[param], **extra))


@pytest.mark.parametrize("light, param, extra, key, words", [
    ("point", "occluder_z", {"reference_step": {"occluder_z": 10}}, "gradient.reference_step.occluder_z",
     ["10 moves the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "occluder_z", {"fd_step": {"occluder_z": 1.6}}, "gradient.fd_step.occluder_z",
     ["the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "light_height", {"reference_step": {"light_height": 1.5}}, "gradient.reference_step.light_height",
     ["the light under the occluder's top", "valid: 0 < step < 1.5"]),
    ("point", "occluder_z", {"inverse_starts": [1e30]}, "gradient.inverse_starts",
     ["1e+30 moves occluder_z out of the scene", "|offset| < 0.5"]),
    ("directional", "light_angle", {"inverse_starts": [-0.5, 75]}, "gradient.inverse_starts",
     ["75 moves light_angle out of the scene", "|offset| < 70 degree"]),
    ("point", "occluder_x", {"reference_step": {"occluder_x": 10}}, "gradient.reference_step.occluder_x",
     ["10 moves the occluder out of the image", "valid: 0 < step < 1"]),
])
def test_grad_refuses_what_it_would_ignore_or_measure_in_another_scene(light, param, extra, key, words, tmp_path,
                                                                       capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text(_toml(light, param, extra))
    rc, err = cli_lines(capsys, "grad", cfg, "--compare", "--out", tmp_path / "o")
    assert rc == 2
    one_line(err, str(cfg), key, *words)
    assert not (tmp_path / "o").exists()


# an old flat [gradient] key, its value, and what the refusal must name: the new table and key with the value
OLD_KEYS = [
    ("scene", "box", ['[[scene]] builtin = "occluder_plate"']),
    ("mesh", "bunny.ply", ['[[scene]] builtin = "occluder_mesh", mesh = "bunny.ply"']),
    ("light", "point", ['[[light]] type = "spot"']),
    ("light_height", 2.0, ["[[light]] position = [0, 0, 2.0]", "the kit's [[light]] table"]),
    ("light_angle", 30.0, ['[[light]] type = "directional", direction = [0.5, 0.0, -0.866025403784]']),
    ("occluder_height", 0.5, ["[[scene]] height = 0.5"]),
    ("occluder_size", 0.4, ["[[scene]] size = 0.4"]),
    ("box_height", 0.02, ["[[scene]] box_height = 0.02"]),
    ("map_resolution", 64, ["[map] resolution = 64"]),
    ("techniques", ["nearest", "vsm"], ['[map] kind = ["depth", ...]', "filter = [...]"]),
    ("blur", [1, 3], ["[map] blur = [1, 3]"]),
    ("antialias", [False, True], ["[map] antialias = [false, true]"]),
    ("bias", 0.06, ['[[scheme]] name = "constant", bias = 0.06']),
    ("light_size", 0.5, ["[[light]] size = 0.5", "gradient.pcss_light_size"]),
]


@pytest.mark.parametrize("key, value, words", OLD_KEYS)
def test_an_old_gradient_key_is_refused_naming_its_new_table_and_key(key, value, words, tmp_path, capsys):
    """Each key the flat [gradient] table had for the scene, light, map and bias: one line naming where it
    lives now (with the value, where one carries over), exit 2, before any work."""
    cfg = tmp_path / "g.toml"
    raw = config(map_resolution=32, image_resolution=32)
    raw["gradient"][key] = value
    cfg.write_text(toml(raw))
    rc, err = cli_lines(capsys, "grad", cfg, "--out", tmp_path / "o")
    assert rc == 2
    one_line(err, str(cfg), f"gradient.{key}", "moved: give", *words)
    assert not (tmp_path / "o").exists()


def test_every_old_key_is_named_and_none_is_read():
    """OLD_KEYS covers every key the refusal knows, and none of them is also a key [gradient] reads."""
    assert sorted(k for k, _, _ in OLD_KEYS) == sorted(specmod.MOVED)
    assert not set(specmod.MOVED) & set(specmod.KEYS)


def _with(table: str, patch, **kw) -> dict:
    raw = config(map_resolution=32, image_resolution=32, **kw)
    if isinstance(raw.get(table), list) and isinstance(patch, dict):
        raw[table][0].update(patch)
    elif patch is None:
        raw.pop(table)
    else:
        raw[table] = patch if not isinstance(raw.get(table), dict) else {**raw[table], **patch}
    return raw


@pytest.mark.parametrize("table, patch, kw, key, words", [
    # one scene, one light
    ("scene", [{"builtin": "occluder_plate"}, {"builtin": "occluder_box"}], {}, "scene[1]", "exactly one [[scene]]"),
    ("light", [{"type": "spot", "position": [0, 0, 2.0], "direction": [0, 0, -1]}] * 2, {}, "light[1]",
     "exactly one [[light]]"),
    ("scene", None, {}, "scene", "needs one [[scene]]"),
    ("light", None, {}, "light", "needs one [[light]]"),
    ("scene", {"builtin": "plane_box"}, {}, "scene[0].builtin", "valid: occluder_plate, occluder_box, occluder_mesh"),
    ("scene", {"scale": 2.0}, {}, "scene[0].scale", "valid: builtin, height, size"),
    # the light: what dsm grad differentiates, or why not
    ("light", {"type": "point"}, {}, "light[0].type", "'point' has no gradient: its cube and paraboloid views"),
    ("light", {"direction": [0.3, 0.2, -0.9]}, {"light": "directional"}, "light[0].direction", "no y component"),
    ("light", {"direction": [0.9, 0.0, -0.2]}, {"light": "directional"}, "light[0].direction",
     "valid: -60 to 60 degrees"),
    ("light", {"position": [0.1, 0.0, 2.0]}, {}, "light[0].position", "straight above the origin"),
    ("light", {"direction": [0.1, 0.0, -1.0]}, {}, "light[0].direction", "faces straight down (valid: [0, 0, -1])"),
    ("light", {"cutoff": 40}, {}, "light[0].cutoff", "fits the spot's cone"),
    ("light", {"shape": "disk"}, {"light": "area"}, "light[0].shape", "a square"),
    ("light", {"size": [0.2, 0.3]}, {"light": "area"}, "light[0].size", "a square"),
    ("light", {"min_samples": 32}, {"light": "area"}, "light[0].min_samples", "gradient.light_samples"),
    # the map
    ("map", {"filter": ["pcf_wide"]}, {}, "map.filter", "'pcf_wide' has no gradient"),
    ("map", {"kind": ["vsm"], "filter": ["nearest"]}, {}, "map.filter", "map.kind names no depth"),
    ("map", {"kind": ["depth"], "filter": ["nearest"], "blur": [3]}, {}, "map.blur", "names none"),
    ("map", {"antialias": "yes"}, {}, "map.antialias", "expected false, true or [false, true]"),
    ("map", {"resolution": [32, 64]}, {}, "map.resolution", "one map resolution"),
    ("map", {"format": "unorm16"}, {}, "map.format", "unknown key"),
    ("map", {"kind": ["depth", "depth"]}, {}, "map.kind", "given twice"),
    # the bias
    ("scheme", {"name": "slope_scaled"}, {}, "scheme[0].name", "got 'slope_scaled' (valid: constant)"),
    ("scheme", {"bias": "2 texel"}, {}, "scheme[0].bias", "world units"),
    ("scheme", {"bias": [0.01, 0.02]}, {}, "scheme[0].bias", "one bias, got 2"),
    ("scheme", [{"name": "constant"}], {}, "scheme[0].bias", "bias in world units, e.g. bias = 0.02"),
    ("scheme", None, {}, "scheme", "need a [[scheme]] for their bias"),
    ("scheme", [{"name": "constant", "bias": 0.02}], {"techniques": ["vsm"]}, "scheme", "does not name depth"),
    # the rest
    ("camera", {"fov": 40}, {}, "camera", "dsm grad does not read this table"),
    ("gradient", {"pcss_light_size": 0.2}, {"light": "area"}, "gradient.pcss_light_size", "the light's own"),
])
def test_a_bad_kit_table_is_one_line_naming_file_key_and_choices(table, patch, kw, key, words):
    with pytest.raises(ConfigError) as e:
        specmod.parse(_with(table, patch, **kw), "g.toml")
    msg = str(e.value)
    assert msg.startswith(f"g.toml: {key}: ") and words in msg and "\n" not in msg, msg


def test_the_kit_tables_give_the_spec_the_light_and_map_they_name():
    """A directional light's direction [sin a, 0, -cos a] is a tilt of a degrees (toward +x); the techniques are
    kinds x (filters or blurs) x antialias in the tables' order; the spot's target below it is its axis."""
    raw = config(light="directional", light_angle=-35.0, techniques=["pcf_bilinear", "nearest", "msm"], blur=[3, 1],
                 antialias=[True, False], bias=0.05, map_resolution=96, pcss_light_size=0.3)
    spec = specmod.parse(raw, "g.toml")
    assert spec.light == "directional" and spec.light_angle == -35.0
    a = math.radians(-35.0)
    assert raw["light"][0]["direction"] == [math.sin(a), 0.0, -math.cos(a)]
    assert [t.label for t in spec.techniques] == ["pcf_bilinear aa", "pcf_bilinear", "nearest aa", "nearest",
                                                 "msm blur 3 aa", "msm blur 3", "msm blur 1 aa", "msm blur 1"]
    assert (spec.bias, spec.map_resolution, spec.light_size) == (0.05, 96, 0.3)
    aimed = config(light_height=2.5)
    aimed["light"][0].pop("direction")
    aimed["light"][0]["target"] = [0.0, 0.0, 0.0]
    assert specmod.parse(aimed, "g.toml").light_height == 2.5


def test_the_new_tables_read_from_toml_equal_the_dict(tmp_path):
    """A config written as TOML (the experiments' form) and the same dict give one GradSpec, source aside."""
    raw = config(scene="box", box_height=0.1, light="area", light_size=0.3, techniques=["pcss", "evsm"], blur=[5])
    cfg = tmp_path / "g.toml"
    cfg.write_text(toml(raw))
    assert tomllib.loads(cfg.read_text()) == raw
    import dataclasses
    assert dataclasses.replace(specmod.load(cfg), source="x") == dataclasses.replace(specmod.parse(raw), source="x")


def test_dsm_run_refuses_the_map_antialias_key_in_one_line():
    """[map] antialias is dsm grad's alone: dsm run's reader says so instead of ignoring it."""
    from dsm.config import read
    raw = {"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}], "map": {"antialias": True}}
    with pytest.raises(ConfigError) as e:
        read.parse(raw, "r.toml")
    msg = str(e.value)
    assert msg.startswith("r.toml: map.antialias: ") and "dsm grad" in msg and "\n" not in msg


def test_a_relative_error_is_undefined_where_the_truth_is_zero_within_its_error():
    from dsm.grad.check import relative_within
    assert relative_within(0.0507, 0.00095, 0.0025) is None       # was 5237.5 %
    assert relative_within(0.0, 0.0, 0.0) is None
    assert relative_within(1.1, 1.0, 0.01) == pytest.approx(0.1)


def test_projective_rows_that_measured_nothing_do_not_agree(tmp_path):
    from types import SimpleNamespace
    from dsm.grad import findings, tables
    blind = SimpleNamespace(value=0.0, error=0.0)
    p = SimpleNamespace(integrator="direct_projective", param="occluder_z", spp=4, grads=[0.0, 0.0], mean=0.0,
                        spread=0.0, primal_mismatch=0.0, ms=1.0)
    assert tables.agrees(p, blind) is None and tables.verdict(p, blind) == "measured nothing"
    tables.write_rows(tmp_path / "projective.csv", tables.PROJECTIVE_COLUMNS, [tables.projective_values(p, blind, None)])
    import csv
    (row,) = csv.DictReader(open(tmp_path / "projective.csv"))
    assert row["agrees"] == "" and row["rel_error"] == ""
    words = findings.projective_words([row])
    assert "agreed with the truth in 0 of 1" in words and "measured nothing" in words


def test_the_words_say_why_no_technique_is_closest_where_the_truth_is_zero_within_its_error():
    from dsm.grad import findings
    rows = [{"technique": t, "param": "occluder_x", "ad": ad, "reference": "0.00095", "reference_error": "0.0025",
             "rel_error": "", "sign": "", "cosine": ""} for t, ad in (("nearest", "0.05"), ("pcss", "0.01"))]
    text = findings.compare_words(rows)
    assert "undefined" in text and "the truth is 0 within its own error" in text and "nearest (" not in text


def test_the_config_reference_spells_dsm_grads_choices_and_keys_as_its_reader():
    """dsm/config/keys.py (below grad/ in the layers) lists [gradient]'s keys, parameters, losses and
    integrators as dsm.grad.spec reads them, and [map] antialias."""
    from dsm.config import keys
    assert {k.name for k in keys.keys_of("gradient")} == set(specmod.KEYS)
    assert keys.GRAD_PARAMS == tuple(specmod.PARAMS) and keys.GRAD_LOSSES == specmod.LOSSES
    assert keys.GRAD_PROJECTIVE == specmod.PROJECTIVE_INTEGRATORS
    assert "antialias" in {k.name for k in keys.keys_of("map")}
