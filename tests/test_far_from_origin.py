"""Scenes far from the origin (docs/far_from_origin.md): what float32 cannot hold is one line naming the key
(translate, scale, the camera), what it holds loads and is measured near the origin."""
from pathlib import Path

import pytest

from conftest import cli_run as _cli, one_line as _one_line, base_config
from dsm import cli


def test_a_builtin_moved_beyond_what_float32_holds_names_translate(tmp_path, capsys):
    """translate = [1e30, 0, 0]: float32 steps there are 7.6e22; the error names translate (it
    named the builtin and "degenerate triangles"); 1e5 still runs."""
    for t, rc in ((1e30, 2), (1e5, 0)):
        cfg = tmp_path / f"t{rc}.toml"
        cfg.write_text(f'[experiment]\nname = "t"\n[[scene]]\nbuiltin = "plane_box"\ntranslate = [{t}, 0.0, 0.0]\n'
                       '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
        capsys.readouterr()
        assert cli.main(["plan", str(cfg)]) == rc
        if rc:
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "scene[0].translate" in err[0] and "float32" in err[0], err


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


@pytest.mark.slow
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


def test_a_mesh_scaled_below_float32_normals_names_the_scale_not_the_camera(tmp_path, capsys):
    """The bunny at scale 1e-20: |e1 x e2| about 1e-42 is below float32's normals (limit 2e-19);
    the message was about the camera's position equal to its target."""
    from conftest import MESHES
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{MESHES / "mitsuba_bunny.ply"}"\nscale = 1e-20\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].scale", "too small for Mitsuba's float32 normals")


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
