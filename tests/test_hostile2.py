"""A hostile new user's tour of the features of issues 28 to 33 (far from the origin, area-light
replicates, pre-filtered maps, contact shadows and shrinking, voxelized shadow volumes, dsm tune's
scan and residual map): each input that gave a traceback, a silently empty or meaningless result,
or a misleading message, with the answer it now gets. Expected values are derived here (counts
of cases by hand, the same case measured another way), not read from the kit."""
import tomllib
from pathlib import Path

import pytest

from conftest import cli_run as _cli, one_line as _one_line, base_config
from dsm.config import read as config
from dsm.config import plan
from dsm.config.read import ConfigError


def _toml(d: dict, prefix: str = "") -> str:
    """``d`` as TOML (scalars, lists of scalars, tables and arrays of tables): the config a user writes."""
    val = lambda v: ("true" if v else "false") if isinstance(v, bool) else repr(v) if not isinstance(v, str) else f'"{v}"'
    flat = lambda v: "[" + ", ".join(val(x) for x in v) + "]" if isinstance(v, list) else val(v)
    plain = {k: v for k, v in d.items() if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict))}
    out = [f"{k} = {flat(v)}" for k, v in plain.items()]
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out += [f"[{name}]", _toml(v, name + ".")]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for t in v:
                out += [f"[[{name}]]", _toml(t, name + ".")]
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------- pre-filtered maps

def _point_light_cfg(views, kinds, schemes):
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                       light=[{"type": "point", "position": [0.6, -0.8, 2.2]}],
                       map={"resolution": 64, "view": views, "kind": kinds}, scheme=schemes)


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


# ---------------------------------------------------------------- dsm tune's table

CAMS3 = [{"position": [3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
         {"position": [-3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
         {"position": [-4.0, -3.0, 5.0], "target": [0.0, 0.0, 0.0], "role": "heldout"}]


def _tune_cfg(tune, schemes=({"name": "constant"},)):
    return {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane"}],
            "map": {"resolution": 32}, "scheme": list(schemes), "tune": tune}


@pytest.mark.parametrize("tune,key,words", [
    # an empty candidate list was an IndexError traceback
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "block": []}}, "tune.bias_map.block", ["empty"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "radius": []}}, "tune.bias_map.radius", ["empty"]),
    ({"camera": CAMS3, "bias_map": {"block": []}}, "tune.bias_map.block", ["empty"]),
    # one scan point is the box's low end alone: table.md gave "tuned / scan" against it
    ({"scan": 1}, "tune.scan", ["both ends"]),
    # Adam's keys were silently ignored by the exact residual fit
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "unit": "world"}}, "tune.bias_map.unit", ["adam"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "lr": 0.1}}, "tune.bias_map.lr", ["adam"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "steps": 5}}, "tune.bias_map.steps", ["adam"]),
])
def test_bad_tune_input_is_one_config_error(tmp_path, capsys, tune, key, words):
    path = tmp_path / "c.toml"
    path.write_text(_toml(_tune_cfg(tune)))
    rc, err = _cli(capsys, "tune", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), key, *words)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_an_infinite_start_names_the_schemes_index_and_tune_params():
    """combined's default slope_clamp is inf: the error named "scheme.slope_clamp" (no index)."""
    from dsm.tune import tuner as tu
    from dsm.config.read import coerce
    cfg = _tune_cfg({}, [{"name": "constant"}, {"name": "combined"}])
    with pytest.raises(ConfigError) as e:
        tu.parse_tune(coerce(cfg))
    assert e.value.key == "scheme[1].slope_clamp" and "tune.params.combined" in str(e.value)
    cfg["tune"] = {"params": {"combined": ["depth_bias"]}}
    assert tu.parse_tune(coerce(cfg)).spec.params["combined"] == ("depth_bias",)


# ---------------------------------------------------------------- a lookup no map reads

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
    path.write_text(_toml(cfg))
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
    path.write_text(_toml(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, "map.view", "point light", "spot light")


# ---------------------------------------------------------------- contact shadows under an area light

def test_contact_columns_under_an_area_light_use_its_lit_and_umbra_regions():
    """Receivers by V* = 1, 1 (lit), 0, 0 (umbra), 0.5, 0.5 (penumbra, in neither count, as the core
    metrics): the march darkens receivers 0, 2, 4, 5. By hand: false shadow 1 (receiver 0; the
    penumbra's receiver 4 was counted too), recovered 1 (receiver 2), nothing missed; after it
    acne 1 of 2 lit, peter-panning 0 of 2 umbra, error 1 of 6, mean |V - V*| (1 + .5 + .5) / 6."""
    import numpy as np
    from dsm.contact import march as contact
    v_frac = np.array([1.0, 1.0, 0.0, 0.0, 0.5, 0.5])
    v = np.array([1.0, 1.0, 1.0, 0.0, 1.0, 0.0])
    occ = np.array([True, False, True, False, True, True])
    m = contact.case_metrics(v, v_frac >= 0.5, occ, v_frac)     # as the runner passes them
    assert (m["n_contact_false"], m["n_contact_recovered"], m["n_contact_missed"]) == (1, 1, 0)
    assert m["contact_acne_rate"] == 0.5 and m["contact_peterpan_rate"] == 0.0
    assert m["contact_error_rate"] == pytest.approx(1 / 6) and m["contact_mean_abs_error"] == pytest.approx(2 / 6)


def test_an_area_light_runs_contact_error_rate_is_the_documented_sum(run_dict):
    """design.md: contact_error_rate = (n_acne + n_contact_false + n_peterpan - n_contact_recovered)
    / n_receivers. Under an area light recovered (46) exceeded n_peterpan (0) and the sum failed."""
    res = run_dict(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                               light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0],
                                       "size": 0.5, "max_samples": 512}],
                               map={"resolution": 64}, contact={"length": "4 texel"},
                               scheme=[{"name": "constant", "bias": "1 texel"}]))
    (r,) = res.rows
    assert r["n_penumbra"] > 0 and r["n_contact_false"] > 0
    assert r["n_contact_recovered"] <= r["n_peterpan"] and r["n_contact_missed"] <= r["n_peterpan"]
    assert r["contact_error_rate"] == pytest.approx(
        (r["n_acne"] + r["n_contact_false"] + r["n_peterpan"] - r["n_contact_recovered"]) / r["n_receivers"])


# ---------------------------------------------------------------- far from the origin

BUNNY = Path(__file__).resolve().parent.parent / "data" / "meshes" / "mitsuba_bunny.ply"


def _far_run(tmp_path, capsys, text):
    path = tmp_path / "c.toml"
    path.write_text('[experiment]\nname = "f"\n' + text + '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n'
                    '[timing]\nrepeats = 1\n')
    rc, err = _cli(capsys, "run", path, "--out", tmp_path / "out")
    return rc, err, path


def test_a_mesh_file_moved_beyond_what_float32_holds_names_translate(tmp_path, capsys):
    """The bunny and its ground (0.75 across) at 1e7, where float32 steps are 1: the error named
    the file and "shape 'ground' has only degenerate triangles"; a built-in's names translate."""
    rc, err, path = _far_run(tmp_path, capsys, f'[camera]\nresolution = [16, 16]\n[[scene]]\nfile = "{BUNNY}"\n'
                                               'translate = [1e7, 0, 0]\n')
    assert rc == 2
    _one_line(err, str(path), "scene[0].translate", "float32", "steps of 1,")
    assert not (tmp_path / "out" / "metrics.csv").exists()


def test_a_mesh_file_where_float32_still_holds_it_loads(tmp_path):
    """At 1e5 (steps of 1/128) the bunny's ground spans about 96 steps: still loaded."""
    from dsm import pipeline
    sd = pipeline.load_scene(pipeline.scene_spec({"file": str(BUNNY), "translate": [1e5, 0, 0]}), (16, 16))
    assert sd.bbox[0][0] > 1e5 - 1 and sd.bbox[1][0] < 1e5 + 1


def test_camera_relative_with_a_camera_far_from_the_scene_names_the_camera(tmp_path, capsys):
    """Rendered relative to a camera 1e8 away, plane_box (8 across) lies where float32 steps are 8:
    the error named the built-in and its degenerate ground. In world coordinates it runs."""
    cam = '[camera]\nresolution = [16, 16]\nposition = [1e8, 0, 3]\ntarget = [0, 0, 0]\nfov = 0.000004\n'
    rc, err, path = _far_run(tmp_path, capsys, cam + '[[scene]]\nbuiltin = "plane_box"\nprecision = "camera_relative"\n')
    assert rc == 2
    _one_line(err, str(path), "camera.position", "camera_relative", "steps of 8,")


def test_the_precision_line_does_not_suggest_camera_relative_to_camera_relative_cases():
    from dsm.maps import headroom
    row = lambda scene: {"scene": scene, "texel_f32_steps": 0.5, "f32_step": 0.0625}
    assert "precision = \"camera_relative\"" in headroom.summary([row("plane_box(translate=[1e+06,0,0])")])
    line = headroom.summary([row("plane_box(precision=camera_relative)")])
    assert "precision = \"camera_relative\" shows" not in line and "camera far from their receivers" in line


def test_a_motion_case_far_from_the_origin_reports_its_float32_headroom(run_dict):
    """Motion rows left f32_step and texel_f32_steps empty, so a precision-limited motion case
    was never flagged. Receivers about 1e5 from the origin lie where float32's step is 2^-7
    (1e5 is in [2^16, 2^17)); at the origin plane_box's receivers (within 3 of it) have steps
    of at most 2^-22."""
    res = run_dict(base_config(scene=[{"builtin": "plane_box", "translate": [[0, 0, 0], [1e5, 0, 0]]}],
                               camera={"resolution": [32, 32]}, map={"resolution": 64},
                               motion=[{"frames": 2, "camera": "dolly", "offset": [0.0, 0.5, 0.0], "points": 200}],
                               scheme=[{"name": "constant", "bias": "1 texel"}]))
    near, far = res.rows
    assert far["f32_step"] == 2.0 ** -7 and near["f32_step"] <= 2.0 ** -22
    assert far["texel_f32_steps"] < 64 <= near["texel_f32_steps"]
    assert res.run["precision_limited"] == [far["case"]]


CBOX = Path(__file__).resolve().parent.parent / "data" / "meshes" / "cbox_mitsuba" / "cbox.xml"


@pytest.mark.parametrize("key,value", [("up", '"z"'), ("ground", '"no"')])
def test_a_placement_key_on_an_xml_scene_names_that_key(tmp_path, capsys, key, value):
    """The error named scene[0] and "up/ground/...", not the key given (an XML scene takes scale,
    translate and, since issue 77, precision: tests/test_derive.py runs it)."""
    path = tmp_path / "c.toml"
    path.write_text(f'[experiment]\nname = "x"\n[[scene]]\nfile = "{CBOX}"\n{key} = {value}\n'
                    '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), f"scene[0].{key}:", "XML", "precision")


# ---------------------------------------------------------------- area-light reference

def test_an_area_reference_in_chunks_is_the_reference_in_one_launch(monkeypatch):
    """A stage launched every receiver's samples at once: max_samples = 2^20 over a few thousand
    receivers passed 2^32 lanes (Dr.Jit's UInt32 index) and the memory. Now receivers go in
    chunks of at most STAGE_LANES rays; each receiver's samples have their own seeds, so V* is
    the same: here with chunks of one to a few receivers against one launch per stage."""
    import numpy as np
    from dsm.truth import area
    from dsm.config import read as config
    from dsm import pipeline
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [24, 24]},
                      light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5,
                              "max_samples": 512, "tolerance": 0.05}])
    sd = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane_box"}), (24, 24))
    light = sd.lights_for(config.parse(cfg).lights)[0]
    gb = pipeline.gbuffer(sd)
    monkeypatch.setattr(area, "STAGE_LANES", 1 << 30)
    whole = pipeline.light_setup(sd, gb, light, "a").ref
    monkeypatch.setattr(area, "STAGE_LANES", 40)
    chunked = pipeline.light_setup(sd, gb, light, "a").ref
    assert len(whole.hits) > 100 and len(np.unique(whole.samples)) >= 3    # receivers stopped at several stages
    assert np.array_equal(whole.hits, chunked.hits) and np.array_equal(whole.samples, chunked.samples)
    assert np.array_equal(whole.low, chunked.low) and np.array_equal(whole.high, chunked.high)


def test_a_lights_scenes_that_name_no_scene_are_a_config_error(tmp_path, capsys):
    """scenes = ["plane"] beside only plane_box lit nothing: a run of 0 cases, exit 0."""
    light = {"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}
    scene = [{"builtin": "plane_box", "precision": ["world", "camera_relative"]}]
    path = tmp_path / "c.toml"
    path.write_text(_toml(base_config(scene=scene, light=[{**light, "scenes": ["plane"]}])))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "light[0].scenes", "'plane'", "plane_box(precision=camera_relative)")
    for names, lit in ((["plane_box"], 2), (["plane_box(precision=camera_relative)"], 1)):   # a first word; a label
        p = plan.make(config.parse(base_config(scene=scene, light=[{**light, "scenes": names}]), "<test>"))
        assert sum(1 for _, _, _, lights in p.scenes if lights) == lit


# ---------------------------------------------------------------- caster shrinking

def test_a_shrink_that_turns_a_closed_caster_inside_out_is_a_config_error(tmp_path, capsys):
    """plane_box's box is 1 x 1 x 1 (a closed cube): shrunk by 0.5 or more its faces cross and it
    comes out inside out, a larger caster facing in (the watertight bunny shrunk by 5 shadowed
    92 % of the lit receivers, exit 0). The ground is open: it only moves down. Just below half
    it still runs."""
    from dsm.scenes import load as scenes
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [16, 16]},
                      map={"resolution": 16, "shrink": 0.5})
    path = tmp_path / "c.toml"
    path.write_text(_toml(cfg))
    rc, err = _cli(capsys, "run", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), "map.shrink", "'box'", "inside out", "0.5")
    assert not (tmp_path / "out" / "metrics.csv").exists()
    scenes.check(config.parse(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [16, 16]},
                                          map={"resolution": 16, "shrink": 0.49}), "<test>"))


def test_dsm_tune_refuses_an_area_light(tmp_path, capsys):
    """It tuned against V* >= 0.5 and an "oracle" of that hard V*, where dsm run counts acne in the
    lit region alone and computes no oracle for an area light: a number where none is defined."""
    cfg = _tune_cfg({}, [{"name": "constant"}])
    cfg["light"] = [{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}]
    path = tmp_path / "c.toml"
    path.write_text(_toml(cfg))
    rc, err = _cli(capsys, "tune", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), "light[0].type", "area", "directional")


def test_motion_with_an_area_light_is_a_config_error(tmp_path, capsys):
    """It ran: its fixed points' V* was one ray to the light's centre, and its row summed the
    frames' counts beside the last frame's penumbra count and errors (n_gt_lit + n_gt_shadowed +
    n_penumbra was not n_receivers)."""
    cfg = base_config(scene=[{"builtin": "plane_box"}],
                      light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}],
                      motion=[{"frames": 2, "camera": "dolly", "offset": [0.0, 0.5, 0.0], "points": 100}])
    path = tmp_path / "c.toml"
    path.write_text(_toml(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "light[0].type", "[[motion]]", "point")


def test_a_range_contact_length_beside_a_vsv_grid_is_a_config_error(tmp_path, capsys):
    """A VSV view's near and far are 0 and 1 (its depth is a fraction of the alpha range), so a
    contact length of "0.5 range" marched 0.5 world units there, not half a depth range."""
    point = {"type": "point", "position": [0.6, -0.8, 2.2]}
    cfg = base_config(scene=[{"builtin": "plane_box"}], light=[point], map={"resolution": 32, "view": ["cube", "vsv"]},
                      scheme=[{"name": "constant"}, {"name": "vsv"}], contact={"length": "0.5 range"})
    path = tmp_path / "c.toml"
    path.write_text(_toml(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "contact.length", "vsv", "texel")
    cfg["map"]["view"] = ["cube"]
    cfg["scheme"] = [{"name": "constant"}]
    assert plan.make(config.parse(cfg, "<test>")).cases == 1          # a depth map's range is defined


def test_a_mesh_scaled_below_float32_normals_names_the_scale_not_the_camera(tmp_path, capsys):
    """The bunny at scale 1e-20: |e1 x e2| about 1e-42 is below float32's normals (limit 2e-19);
    the message was about the camera's position equal to its target."""
    from conftest import MESHES
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{MESHES / "mitsuba_bunny.ply"}"\nscale = 1e-20\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].scale", "too small for Mitsuba's float32 normals")


@pytest.mark.parametrize("tail, what", [("f 2 4", "face with fewer than 3 corners"),
                                        ("v 1 1", "vertex with fewer than 3 coordinates")])
def test_an_obj_cut_mid_record_is_refused_naming_the_line(tmp_path, capsys, tail, what):
    obj = tmp_path / "cut.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n" + tail)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[[scene]]\nfile = "cut.obj"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].file", "line 6", what)


@pytest.mark.parametrize("over, key, words", [
    ({"map": {"resolution": [64, 128, 64]}}, "map.resolution", ("64 is given twice",)),
    ({"map": {"resolution": 64, "filter": ["nearest", "pcss", "nearest"]}}, "map.filter", ("nearest is given twice",)),
    ({"map": {"resolution": 64, "format": ["unorm16", "unorm16"]}}, "map.format", ("unorm16 is given twice",)),
    # "1 texel" and "1.0 texel" are one length: the same instance twice
    ({"scheme": [{"name": "constant", "bias": ["1 texel", "2 texel", "1.0 texel"]}]}, "scheme[0].bias",
     ("'1.0 texel' is given twice", "as '1 texel'")),
    ({"scheme": [{"name": "none"}, {"name": "constant", "bias": 0.1}, {"name": "constant", "bias": [0.2, 0.1]}]},
     "scheme[2]", ("constant bias=0.1", "already scheme[1]'s")),
])
def test_a_repeated_case_dimension_is_refused(over, key, words):
    """A value given twice in a case dimension would run the same cases twice under two ids (and a
    resumed run could not tell them apart): refused, naming the key and the repeated value."""
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(**over))
    msg = str(e.value)
    assert key in msg and all(w in msg for w in words), msg


def test_an_xml_scene_scaled_past_float32_names_the_scale_not_the_file(tmp_path, capsys):
    """The Cornell box at scale 1e20 fails in Mitsuba's OBJ loader (its normals overflow float32);
    the file loads unscaled, so the message names scene[0].scale (it named scene[0].file)."""
    from conftest import MESHES
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{MESHES / "cbox_mitsuba" / "cbox.xml"}"\nscale = 1e20\n'
                   '[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].scale", "scaled by 1e+20", "it loads as it is")
    assert not (tmp_path / "o").exists()
    # a file that does not load at all still names the file, and the line of the file as it is (the
    # scaled text Mitsuba read has its lines moved by the inserted transforms)
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <shape type="rectangle"/>\n  <shape type="nosuch"/>\n</scene>\n')
    cfg.write_text(f'[[scene]]\nfile = "{bad}"\nscale = 1e20\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].file", "line 3,", "nosuch")


def test_an_unknown_key_of_an_xml_scene_lists_the_keys_an_xml_scene_takes(tmp_path, capsys):
    """An XML scene's unknown key lists what an XML scene takes (it listed a mesh file's keys, such
    as ground and up, which an XML scene refuses)."""
    from conftest import MESHES
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{MESHES / "cbox_mitsuba" / "cbox.xml"}"\nbogus = 1\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "scene[0].bogus", "unknown key", "scale", "translate")
    assert "ground" not in err[0] and "up," not in err[0]


def test_an_xml_moved_too_far_is_measured_near_the_origin(tmp_path, capsys):
    """The Cornell box at 1e9: the limit is computed from its size measured near the origin (the
    file loaded as it is), not from bounds rounded to float32's steps of 64 there."""
    import re

    import mitsuba as mi
    import numpy as np
    from conftest import MESHES
    xml = MESHES / "cbox_mitsuba" / "cbox.xml"
    bb = mi.load_file(str(xml)).bbox()
    size = float(np.max(np.array(bb.max, np.float64) - np.array(bb.min, np.float64)))
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{xml}"\ntranslate = [1e9, 0, 0]\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "scene[0].translate", "steps of 64")
    said = float(re.search(r"the scene is ([0-9.e+]+) across", err[0]).group(1))
    assert abs(said - size) <= 0.005 * size, (said, size)
    limit = float(re.search(r"below ([0-9.e+]+)\)", err[0]).group(1))
    assert abs(limit - size / 64 * 2 ** 23) <= 0.005 * limit


# ---------------------------------------------------------------- dsm tune's hostile tour (issue 29)

TUNE_CAMS = ('[[tune.camera]]\nposition = [3.0, -5.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n'
             '[[tune.camera]]\nposition = [-4.0, -3.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\nrole = "heldout"\n')


@pytest.mark.parametrize("extra, key, words", [
    ("[tune]\nseed = -7\n", "tune.seed", ">= 0"),
    ("[tune]\nlambda = 1e30\n", "tune.lambda", "<= 1000000"),
    ("[oracle]\nlambda = [1.0, 1e9]\n", "oracle.lambda", "<= 1000000"),
    ('[tune]\n' + TUNE_CAMS + '[[tune.camera]]\nposition = [3.0, -5.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n'
     'role = "heldout"\nname = "twin"\n', "tune.camera[2]", "same pose"),
])
def test_tune_refuses_absurd_values_before_any_work(tmp_path, capsys, extra, key, words):
    """A negative seed (numpy refuses it mid-run), a weight that overflows the relaxed loss, a held-out
    camera on a training camera's pose: one line naming the key, exit 2, nothing written."""
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\n[[scene]]\nbuiltin = "l_shape"\n[[scheme]]\nname = "constant"\n' + extra)
    rc, err = _cli(capsys, "tune", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, key, words)
    assert not (tmp_path / "o").exists()


def test_a_negative_experiment_seed_is_refused(tmp_path, capsys):
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\nseed = -3\n[[scene]]\nbuiltin = "plane"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "experiment.seed", ">= 0")


def test_an_empty_out_is_refused_and_default_folders_never_collide(tmp_path, capsys, monkeypatch):
    """--out '' is a mistake, not the default; two default folders made in one second differ."""
    from dsm import cli
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\n[[scene]]\nbuiltin = "plane"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", "")
    assert rc == 2
    _one_line(err, "--out", "empty")
    monkeypatch.chdir(tmp_path)
    a, b = cli.fresh_folder("t"), cli.fresh_folder("t")
    assert a != b and a.is_dir() and b.is_dir() and a.parent == b.parent == Path("runs")


def test_a_start_outside_its_range_is_noted(tmp_path):
    """[tune.range] that leaves out a scheme's start: the search begins from the start clipped into the
    box, and the notes say so (the result may be worse than the start)."""
    from dsm.tune import tuner as tu
    cfg = tomllib.loads('[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "l_shape"\n'
                        '[map]\nresolution = 32\n[[scheme]]\nname = "constant"\nbias = "1 texel"\n'
                        '[tune]\nsteps = 6\nrange.constant = { bias = [3.0, 4.0] }\n')
    res = tu.tune(cfg)
    assert res.schemes[0]["start_outside_box"] == ["bias"]
    assert 3.0 <= res.schemes[0]["values"]["bias"] <= 4.0
    assert any("outside its [tune.range] box" in n for n in res.notes)
    assert any("no [[tune.camera]]" in n for n in res.notes)


def test_a_one_point_grid_is_the_box_centre_and_said(tmp_path):
    """steps below 2^p leave the grid one point a parameter: the box's centre (not its lower corner,
    all zeros), and table.md says it compares nothing."""
    from dsm.tune import tuner as tu
    from dsm.tune.output import table_text
    cfg = tomllib.loads('[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "l_shape"\n'
                        '[map]\nresolution = 32\n[[scheme]]\nname = "combined"\nnormal_offset = "1 texel"\n'
                        'depth_bias = "0.5 texel"\nslope_scale = 0.5\nslope_clamp = "4 texel"\n[tune]\nsteps = 6\n')
    res = tu.tune(cfg)
    e = res.schemes[0]
    assert e["grid"]["points_per_parameter"] == 1
    for name, (lo, hi) in e["box"].items():
        assert e["grid"]["values"][name] == pytest.approx(0.5 * (lo + hi))
    assert "a grid of one point per parameter" in table_text(res)


def test_ctrl_c_while_the_command_starts_is_one_line(monkeypatch, capsys):
    """The dsm command's entry point (dsm.launch): a Ctrl-C while the command line's modules import
    ends it with one line and exit 130, not a traceback."""
    import builtins
    import sys
    from dsm import launch
    real = builtins.__import__

    def interrupted(name, globals=None, locals=None, fromlist=(), level=0):
        if (level == 1 and name == "cli") or name == "dsm.cli":
            raise KeyboardInterrupt
        return real(name, globals, locals, fromlist, level)
    monkeypatch.delitem(sys.modules, "dsm.cli", raising=False)
    monkeypatch.setattr(builtins, "__import__", interrupted)
    assert launch.main() == 130
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err == ["dsm: interrupted (while starting)"]
