"""Every bad input is one or two lines on stderr (no traceback) with a meaningful exit status,
before any work starts; the inputs here are the ones that used to crash, hang or mislead."""
import json
import math
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import base_config, cli_run as _cli

from dsm import cli
from dsm.config import read as config
from dsm.config import plan
from dsm.scenes import builtins as scene_builtins, geometry, load as scenes, params as scene_params
from dsm.config.read import ConfigError, Length

ROOT = Path(__file__).resolve().parent.parent
CAM = '''<sensor type="perspective"><transform name="to_world"><lookat origin="0, -4, 3" target="0, 0, 0" up="0, 0, 1"/>
</transform><film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="30"/></film></sensor>'''
SUN = '<emitter type="directional"><vector name="direction" value="0, 0.2, -1"/></emitter>'
PLY_HEAD = ("ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n")


def _tiny(scene: str, extra: str = "") -> str:
    return (f'[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\n{scene}\n'
            f'[map]\nresolution = 32\n[[scheme]]\nname = "none"\n[timing]\nrepeats = 1\n{extra}')


def _size(sd) -> tuple:
    return tuple(int(x) for x in sd.sensor.film().size())


def _one_line(err, *words):
    assert 1 <= len(err) <= 2, err
    assert not any("Traceback" in l for l in err), err
    for w in words:
        assert w in err[0], (w, err[0])


# ---------------------------------------------------------------- 1: scene files

def _bad_files(d: Path) -> dict:
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    body = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2)
    files = {
        "syntax.xml": ('<scene version="3.0.0"><shape type="cube"></scene>', "Start-end tags mismatch"),
        "empty.xml": ("", "is empty"),
        "nosensor.xml": ('<scene version="3.0.0"><shape type="cube"/>' + SUN + "</scene>", "no <sensor>"),
        "missingmesh.xml": (f'<scene version="3.0.0">{CAM}<shape type="obj"><string name="filename" '
                            f'value="nothere.obj"/></shape>{SUN}</scene>', "nothere.obj"),
        # loads in Mitsuba, but its positions are not finite
        "infinite.xml": (f'<scene version="3.0.0">{CAM}<shape type="cube"><transform name="to_world">'
                         f'<scale value="1e39"/></transform></shape>{SUN}</scene>', "not finite"),
        "empty.obj": ("", "is empty"),
        "badface.obj": (tri + "f 1 2 7\n", "invalid vertex 7"),
        "nanvert.obj": ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "invalid vertex position"),
        "nofaces.obj": (tri, "no faces"),
        "trunc_ascii.ply": (PLY_HEAD.format(fmt="ascii") + "0 0 0\n1 0 0\n", "could not parse"),
        "trunc_bin.ply": (PLY_HEAD.format(fmt="binary_little_endian").encode() + body[:20], "read 20 out of 36"),
        "noface.ply": (PLY_HEAD.format(fmt="ascii").replace("element face 1", "element face 0") + "0 0 0\n1 0 0\n0 1 0\n",
                       "no faces"),
    }
    for name, (content, _) in files.items():
        (d / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    return {name: why for name, (_, why) in files.items()}


BAD_FILES = ["syntax.xml", "empty.xml", "nosensor.xml", "missingmesh.xml", "infinite.xml", "empty.obj",
             "badface.obj", "nanvert.obj", "nofaces.obj", "trunc_ascii.ply", "trunc_bin.ply", "noface.ply"]


@pytest.mark.slow
@pytest.mark.parametrize("name", BAD_FILES)
def test_unreadable_scene_file_is_one_line_before_any_work(tmp_path, capsys, name):
    why = _bad_files(tmp_path)[name]
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny(f'file = "{name}"'))
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2, err
    _one_line(err, "config error", str(cfg), "scene[0].file", why)
    assert not (tmp_path / "o").exists()                       # refused before any work
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2 and "scene[0].file" in err[0] and why in err[0], err


def test_plan_lists_every_unreadable_scene(tmp_path, capsys):
    _bad_files(tmp_path)
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"\n[[scene]]\nfile = "empty.obj"\n[[scene]]\nfile = "nosensor.xml"'))
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2 and len(err) == 2, err
    assert "scene[1].file" in err[0] and "scene[2].file" in err[1] and "no <sensor>" in err[1]
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2 and len(err) == 2 and "scene[1].file" in err[0] and "scene[2].file" in err[1], err
    with pytest.raises(ConfigError) as e:                       # the function the runner calls
        scenes.check(config.load(cfg))
    assert e.value.key == "scene[1].file" and [m.key for m in e.value.more] == ["scene[2].file"]


def test_a_readable_file_scene_passes_the_check(tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    cfg = config.parse({"scene": [{"file": "tri.obj"}], "scheme": [{"name": "none"}]}, "<t>", tmp_path)
    [sd] = scenes.check(cfg, keep=True)
    assert _size(sd) == (256, 256) and len(sd.shape_names) == 2      # the mesh and its ground


# ---------------------------------------------------------------- 2: command line

def test_out_that_is_a_file_or_unwritable(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"'))
    (tmp_path / "afile").write_text("x")
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "afile")
    assert rc == 2
    _one_line(err, "is a file")
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "afile" / "sub")
    assert rc == 2
    _one_line(err, "cannot write there")
    rc, err = _cli(capsys, "run", cfg, "--out", "/proc/dsm-no-such/out")      # a read-only file system
    assert rc == 2
    _one_line(err, "cannot write there")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_out_in_a_read_only_folder(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"'))
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o555)
    rc, err = _cli(capsys, "run", cfg, "--out", ro / "sub")
    assert rc == 2
    _one_line(err, "cannot write there")


@pytest.mark.parametrize("args,words", [
    (["--threads", "-3"], ["--threads", "at least 1"]),
    (["--threads", "0"], ["--threads", "at least 1"]),
    (["--variant", "scalar_rgb"], ["--variant", "llvm_ad_rgb"]),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, args, words):
    rc, err = _cli(capsys, "run", "--out", tmp_path / "o", *args)
    assert rc == 2
    _one_line(err, *words)
    assert len(err) == 1 and not (tmp_path / "o").exists()


def test_scalar_variant_is_not_offered():
    assert "scalar_rgb" not in config.VARIANTS
    with pytest.raises(ConfigError, match="experiment.variant"):
        config.parse({"experiment": {"variant": "scalar_rgb"}, "scene": [{"builtin": "plane"}],
                      "scheme": [{"name": "none"}]})


def test_non_utf8_config(tmp_path, capsys):
    cfg = tmp_path / "latin1.toml"
    cfg.write_bytes('[experiment]\nname = "caf\xe9"\n'.encode("latin-1"))
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, str(cfg), "UTF-8", "0xe9")


def test_coerce_accepts_config_dict_and_path_and_refuses_the_rest(tmp_path):
    raw = {"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]}
    c = config.coerce(raw)
    assert config.coerce(c) is c
    (tmp_path / "c.toml").write_text(_tiny('builtin = "plane"'))
    assert config.coerce(tmp_path / "c.toml").camera_resolution == (32, 32)
    assert config.coerce(str(tmp_path / "c.toml")).name == "t"
    with pytest.raises(TypeError) as e:
        config.coerce(42)
    msg = str(e.value)
    assert "\n" not in msg and "int" in msg and "dict" in msg and "TOML" in msg


@pytest.mark.parametrize("name", ["../../escape", "a/b", "..", "a\\b"])
def test_experiment_name_must_be_a_plain_file_name(name):
    with pytest.raises(ConfigError) as e:
        config.parse({"experiment": {"name": name}, "scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]})
    assert e.value.key == "experiment.name" and "plain file name" in str(e.value)


@pytest.mark.slow
def test_force_replaces_a_previous_run_and_nothing_else(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"'))
    out = tmp_path / "o"
    assert _cli(capsys, "run", cfg, "--out", out)[0] == 0
    leftover = next((out / "images").iterdir()) / "0099_error.png"      # a run's image of no current case
    leftover.write_bytes(b"x")
    (out / "images" / "stale.png").write_bytes(b"x")                   # not a name a run writes: the user's
    rc, err = _cli(capsys, "run", cfg, "--out", out)                   # not empty, no --force
    assert rc == 2
    _one_line(err, "not empty", "--force")
    rc, err = _cli(capsys, "run", cfg, "--out", out, "--force")        # a previous run: cleared first
    assert rc == 0, err
    assert not leftover.exists() and json.loads((out / "run.json").read_text())["n_failed"] == 0
    assert (out / "images" / "stale.png").read_bytes() == b"x"
    # a folder with a run.json and a file of the user's: refused, untouched
    (out / "notes.txt").write_text("mine")
    rc, err = _cli(capsys, "run", cfg, "--out", out, "--force")
    assert rc == 2
    _one_line(err, "--force", "notes.txt")
    assert (out / "notes.txt").read_text() == "mine"
    # a non-empty folder that never held a run: refused, untouched
    other = tmp_path / "other"
    other.mkdir()
    (other / "thesis.tex").write_text("mine")
    rc, err = _cli(capsys, "run", cfg, "--out", other, "--force")
    assert rc == 2
    _one_line(err, "--force", "no run.json")
    assert (other / "thesis.tex").read_text() == "mine"


@pytest.mark.slow
def test_ctrl_c_is_one_line_and_exit_130(tmp_path):
    out = tmp_path / "o"
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"from dsm.cli import main; sys.exit(main(['run', '--out', {str(out)!r}]))")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    t0 = time.time()
    while not (out / "run.json").exists() and time.time() - t0 < 120 and p.poll() is None:
        time.sleep(0.1)
    time.sleep(2.0)                              # the default experiment runs for a minute or more
    p.send_signal(signal.SIGINT)
    _, stderr = p.communicate(timeout=120)
    lines = [l for l in stderr.splitlines() if l.strip()]
    assert p.returncode == 130, stderr[-2000:]
    assert "Traceback" not in stderr
    assert len(lines) == 1 and lines[0] == (f"dsm: interrupted (results so far in {out}/); "
                                            f"`dsm run ... --out {out} --resume` runs the rest"), lines


# ---------------------------------------------------------------- 3: variants

def test_cuda_without_a_gpu_is_one_plain_line(tmp_path, capsys):
    import drjit as dr
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("this machine has a CUDA GPU")
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"'))
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o", "--variant", "cuda_ad_rgb")
    assert rc == 3 and err == ["dsm: setup error: variant cuda_ad_rgb needs an NVIDIA GPU with CUDA; none found "
                               "here: use llvm_ad_rgb"], err
    import mitsuba as mi
    assert mi.variant() == "llvm_ad_rgb"          # left as it was


# ---------------------------------------------------------------- 4: nothing to run

def test_every_scene_absent_says_which_and_where(tmp_path, capsys):
    moved = tmp_path / "moved" / "sponza_dabrovic.ply"
    cfg = tmp_path / "two.toml"
    cfg.write_text(_tiny(f'file = "{moved}"\noptional = true', '[[scene]]\nfile = "gone/bunny.ply"\noptional = true\n'))
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 1
    _one_line(err, "nothing to run", "sponza_dabrovic.ply", "bunny.ply", str(moved.parent), "put the files at those paths")
    assert not (tmp_path / "o").exists()
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 1
    _one_line(err, "nothing to run", "sponza_dabrovic.ply")


def test_a_shipped_experiments_mesh_is_not_optional(tmp_path, capsys):
    """The meshes ship with the kit: a shipped experiment whose mesh is gone is a config error
    naming the file (exit 2), never a silent skip."""
    text = (ROOT / "experiments" / "real_meshes.toml").read_text()
    assert 'file = "../data/meshes/mitsuba_bunny.ply"\n[[scene]]' in text       # the first scene, not optional
    cfg = tmp_path / "real.toml"
    cfg.write_text(text.replace("../data/meshes/mitsuba_bunny.ply", str(tmp_path / "gone.ply")))
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "scene[0].file", "gone.ply")


# ---------------------------------------------------------------- 5: memory

def test_plan_warns_when_maps_exceed_the_budget(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"', "[memory]\nbudget_mb = 1\n").replace("resolution = 32\n[[scheme]]",
                                                                                      "resolution = 1024\n[[scheme]]"))
    capsys.readouterr()
    assert cli.main(["plan", str(cfg)]) == 0
    warnings = [l for l in capsys.readouterr().out.splitlines() if "warning:" in l]
    assert len(warnings) == 1 and "cast in tiles" in warnings[0] and "memory budget of 1 MB" in warnings[0]


def test_plan_without_tiles_has_no_warning():
    p = plan.make(config.parse({"camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane"}],
                                "map": {"resolution": 32}, "scheme": [{"name": "none"}]}))
    assert "warning" not in p.text()


def test_plan_counts_the_camera_buffers():
    small = plan.make(config.parse({"camera": {"resolution": [64, 64]}, "scene": [{"builtin": "plane"}],
                                    "map": {"resolution": 32}, "scheme": [{"name": "none"}]}))
    big = plan.make(config.parse({"camera": {"resolution": [2048, 2048]}, "scene": [{"builtin": "plane"}],
                                  "map": {"resolution": 32}, "scheme": [{"name": "none"}]}))
    # G-buffer (150 B/px measured), reference and host images per pixel, and the one case's
    # lookup wave (its outputs on the device and their numpy copies)
    per_pixel = plan.PIXEL_BYTES + 2 * plan.WAVE_RECEIVER_BYTES
    assert big.peak_bytes() - small.peak_bytes() == (2048 ** 2 - 64 ** 2) * per_pixel
    assert plan.PIXEL_BYTES >= plan.GBUFFER_BYTES + plan.REFERENCE_BYTES


def test_a_run_larger_than_this_machine_is_refused(tmp_path, capsys, monkeypatch):
    # the machine's memory is set to this one's 24 GiB, so the test never depends on (or runs
    # a 16384^2 camera on) a larger machine: 16384^2 x PIXEL_BYTES is about 68 GiB
    monkeypatch.setattr(plan, "physical_memory", lambda: 24 << 30)
    assert 16384 ** 2 * plan.PIXEL_BYTES > 24 << 30
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny('builtin = "plane"').replace("[32, 32]", "[16384, 16384]"))
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "camera.resolution", "exceeds this machine's")
    assert not (tmp_path / "o").exists()
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2 and "camera.resolution" in err[0]
    # the function dsm.run calls, with a smaller machine: a big map is named as the cause
    p = plan.make(config.parse({"camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane"}],
                                "map": {"resolution": 4096}, "scheme": [{"name": "none"}]}))
    with pytest.raises(ConfigError) as e:
        plan.check_memory(p, "<t>", available=32 << 20)
    assert e.value.key == "map.resolution"
    plan.check_memory(p, "<t>", available=1 << 40)


# ---------------------------------------------------------------- 6: numbers a user can trust

def test_length_fields_honour_their_minimum():
    import dataclasses

    @dataclasses.dataclass(frozen=True)
    class P:
        limit: Length = dataclasses.field(default=Length(1.0), metadata={"min": 0.0})
        free: Length = Length(1.0)

    f = {x.name: x for x in dataclasses.fields(P)}
    assert config.coerce_field(f["limit"], "2 texel", "<t>", "k") == Length(2.0, "texel")
    assert config.coerce_field(f["limit"], 0, "<t>", "k") == Length(0.0)
    with pytest.raises(ConfigError, match=">= 0"):
        config.coerce_field(f["limit"], "-8 texel", "<t>", "k")
    assert config.coerce_field(f["free"], -1, "<t>", "k") == Length(-1.0)


@pytest.mark.parametrize("scheme,key", [
    ({"name": "slope_scaled", "clamp": -1}, "scheme[0].clamp"),
    ({"name": "normal_angle", "max": "-8 texel"}, "scheme[0].max"),
    ({"name": "dual", "z_offset": "-4 texel"}, "scheme[0].z_offset"),
    ({"name": "adaptive", "K": -1e-4}, "scheme[0].K"),
])
def test_negative_upper_limits_are_refused(scheme, key):
    """Needs metadata={"min": 0.0} on these fields in dsm/schemes/ (K already has it)."""
    with pytest.raises(ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane"}], "scheme": [scheme]}, "<t>")
    assert e.value.key == key and ">= 0" in str(e.value)


def test_map_view_without_a_point_light():
    base = {"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}], "map": {"view": "cube"}}
    with pytest.raises(ConfigError) as e:
        config.parse({**base, "light": [{"type": "directional", "direction": [0, 0, -1]}]}, "<t>")
    assert e.value.key == "map.view" and "point" in str(e.value)
    config.parse({**base, "light": [{"type": "point", "position": [0, 0, 2]}]}, "<t>")
    config.parse(base, "<t>")                      # the scene's own lights may be point lights


def test_closed_override_must_name_a_shape(tmp_path):
    with pytest.raises(ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane_box", "closed": {"boxx": True}}], "scheme": [{"name": "none"}]})
    assert e.value.key == "scene[0].closed.boxx" and e.value.choices == ("ground", "box")
    xml = tmp_path / "s.xml"
    xml.write_text(f'<scene version="3.0.0">{CAM}<shape type="cube" id="block"/>{SUN}</scene>')
    cfg = config.parse({"scene": [{"file": str(xml), "closed": {"blok": True}}], "scheme": [{"name": "none"}]}, "<t>")
    with pytest.raises(ConfigError) as e:
        scenes.check(cfg)
    assert e.value.key == "scene[0].closed.blok" and "block" in e.value.choices


# ---------------------------------------------------------------- 7: translate

@pytest.mark.slow
def test_translate_moves_geometry_camera_and_config_lights(run_dict):
    lights = [{"type": "directional", "direction": [-0.3, -0.2, -1.0]},
              {"type": "spot", "position": [-1.5, 1.0, 3.0], "target": [0.0, 0.0, 0.0], "cutoff": 40}]
    base = {"camera": {"resolution": [48, 48]}, "map": {"resolution": 64}, "light": lights,
            "scheme": [{"name": "receiver_plane"}], "timing": {"repeats": 1}}
    cfg = config.parse({**base, "scene": [{"builtin": "plane_box", "translate": [[0, 0, 0], [1000, -2000, 300]]}]})
    assert [s.label for s in cfg.scenes] == ["plane_box", "plane_box(translate=[1000,-2000,300])"]
    sd = scenes.load(cfg.scenes[1], (8, 8))
    assert np.allclose(sd.bbox[0], [996, -2004, 300]) and np.allclose(sd.bbox[1], [1004, -1996, 301])
    assert np.allclose(sd.lights_for(cfg.lights)[1].position, [998.5, -1999.0, 303.0])
    res = run_dict({**base, "scene": [{"builtin": "plane_box", "translate": [[0, 0, 0], [1000, -2000, 300]]}]})
    near, far = res.rows[:2], res.rows[2:]
    assert len(res.rows) == 4 and res.run["n_failed"] == 0
    for a, b in zip(near, far):
        assert a["light"] == b["light"] and abs(a["n_receivers"] - b["n_receivers"]) <= 0.01 * a["n_receivers"]
        assert abs(a["n_gt_shadowed"] - b["n_gt_shadowed"]) <= 0.05 * a["n_gt_shadowed"] + 2


def test_translate_must_be_three_numbers():
    with pytest.raises(ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane", "translate": [1, 2]}], "scheme": [{"name": "none"}]})
    assert e.value.key == "scene[0].translate"


# ---------------------------------------------------------------- 8: double torus

@pytest.mark.slow
def test_double_torus_is_a_closed_genus_two_mesh(run_dict):
    from dsm.scenes.closedness import shape_closedness
    cfg = config.parse({"scene": [{"builtin": "double_torus"}], "scheme": [{"name": "none"}]})
    sd = scenes.load(cfg.scenes[0], (8, 8))
    shape = sd.scene.shapes()[sd.shape_names.index("double_torus")]
    assert shape_closedness(shape) == (True, "closed")                  # outward, every edge shared twice
    f = np.array(shape.faces_buffer()).reshape(-1, 3)
    edges = {tuple(sorted(e)) for t in f for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    assert shape.vertex_count() - len(edges) + len(f) == 2 - 2 * 2      # Euler characteristic: genus 2
    assert 2000 <= len(f) <= 8000
    res = run_dict({"scene": [{"builtin": "double_torus"}], "camera": {"resolution": [48, 48]},
                    "map": {"resolution": 64}, "timing": {"repeats": 1},
                    "scheme": [{"name": "midpoint"}, {"name": "dual", "culling": "back_closed"}]})
    assert res.run["n_failed"] == 0 and all(r["n_gt_shadowed"] > 50 and r["n_gt_lit"] > 50 for r in res.rows)


# ---------------------------------------------------------------- 9: the XML camera

def test_xml_film_is_the_camera_unless_camera_resolution_is_given(tmp_path):
    xml = tmp_path / "s.xml"
    xml.write_text(f'<scene version="3.0.0">{CAM}<shape type="rectangle"/>{SUN}</scene>')
    cfg = config.parse({"scene": [{"file": str(xml)}], "scheme": [{"name": "none"}]}, "<t>")
    assert cfg.camera_resolution is None
    assert _size(scenes.load(cfg.scenes[0], cfg.camera_resolution)) == (40, 30)
    assert plan.make(cfg).scenes[0][1:3] == (40, 30)
    cfg = config.parse({"scene": [{"file": str(xml)}], "camera": {"resolution": [64, 64]},
                        "scheme": [{"name": "none"}]}, "<t>")
    sd = scenes.load(cfg.scenes[0], cfg.camera_resolution)
    assert _size(sd) == (64, 48) and plan.make(cfg).scenes[0][1:3] == (64, 48)
    own = scenes.load(config.parse({"scene": [{"file": str(xml)}], "scheme": [{"name": "none"}]}, "<t>").scenes[0])
    assert np.allclose(sd.sensor.world_transform().matrix.numpy(), own.sensor.world_transform().matrix.numpy())
    # built-ins without [camera]: 256 x 256
    b = config.parse({"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]})
    assert plan.make(b).scenes[0][1:3] == (256, 256)
    assert _size(scenes.load(b.scenes[0])) == (256, 256)


# ---------------------------------------------------------------- 10: default light at the centre

def test_area_light_at_the_scene_centre_gets_a_defined_light(tmp_path, run_dict):
    xml = tmp_path / "centre.xml"
    xml.write_text(f'''<scene version="3.0.0">{CAM.replace('origin="0, -4, 3" target="0, 0, 0"',
                                                           'origin="0, -4, 0.5" target="0, 0, -0.8"')}
<shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="-1"/></transform></shape>
<shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="1"/></transform></shape>
<shape type="cube"><transform name="to_world"><scale value="0.2"/><translate z="-0.7"/></transform></shape>
<shape type="rectangle"><transform name="to_world"><scale value="0.2"/><rotate x="1" angle="180"/></transform>
<emitter type="area"/></shape></scene>''')
    cfg = config.parse({"scene": [{"file": str(xml)}], "scheme": [{"name": "none"}]}, "<t>")
    sd = scenes.load(cfg.scenes[0])
    [light] = sd.own_lights
    assert all(math.isfinite(c) for c in light.direction + light.position)
    assert np.allclose(light.direction, (0, 0, -1), atol=1e-6) and light.position[2] < 0   # the emitting side
    res = run_dict({"scene": [{"file": str(xml)}], "map": {"resolution": 32, "view": "cube"},
                    "scheme": [{"name": "receiver_plane"}], "timing": {"repeats": 1}})
    [row] = res.rows
    assert row["n_gt_shadowed"] > 10 and row["acne_rate"] < 0.2       # the cube shadows the floor


def test_normalize_refuses_a_zero_vector():
    with pytest.raises(ValueError, match="zero"):
        geometry.normalize([0.0, 0.0, 0.0])


# ---------------------------------------------------------------- 11: scale

def test_scale_beyond_float32_normals_is_refused(run_dict):
    """Mitsuba's triangle normals overflow in float32 (plane_box keeps 2488 receivers at scale
    3e8 and 75 at 1e9): refused at the limit, which the message names."""
    lo, hi = scene_builtins.scale_range("plane_box", scene_params.PlaneBoxParams())
    assert lo < 1e-9 and 1e8 < hi < 5.4e8
    with pytest.raises(ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane_box", "scale": 1e9}], "scheme": [{"name": "none"}]}, "<t>")
    assert e.value.key == "scene[0].scale" and f"{hi:.2g}" in str(e.value)
    base = {"camera": {"resolution": [32, 32]}, "map": {"resolution": 32}, "scheme": [{"name": "none"}],
            "timing": {"repeats": 1}}
    res = run_dict({**base, "scene": [{"builtin": "plane_box", "scale": [1.0, 1e8]}]})
    a, b = res.rows
    assert a["n_receivers"] > 500 and abs(a["n_receivers"] - b["n_receivers"]) <= 5


@pytest.mark.parametrize("over, key", [
    ({"map": {"resolution": 32, "kind": ["depth", "vsm"], "blur": [3, 3]}}, "map.blur"),
    ({"map": {"resolution": 32, "kind": ["depth", "vsm"], "vsm": {"preset": ["three", "three"]}}}, "map.vsm.preset"),
    ({"map": {"resolution": 32, "kind": ["depth", "vsm"], "vsm": {"min_variance": [1e-4, 1e-4]}}},
     "map.vsm.min_variance"),
    ({"scene": [{"builtin": "plane_box", "translate": [[0, 0, 0], [0, 0, 0]]}]}, "scene[0].translate"),
    ({"map": {"resolution": 32, "kind": ["depth", "evsm"], "evsm": {"moments": 2, "negative": 10}}},
     "map.evsm.negative"),
    ({"map": {"resolution": 32, "kind": ["depth", "vsm"], "vsm": {"min_variance": 1e39}}}, "map.vsm.min_variance"),
    ({"contact": {"length": 0.1, "length_depth_min": 0.5}}, "contact.length_depth_min"),
])
def test_silent_input_is_refused_naming_the_key(over, key):
    """A value given twice would run and pool the same cases twice; a key the chosen mode does not
    read, or a minimum variance no depth distribution on [0, 1] reaches (V NaN), would pass unseen."""
    from dsm.config import read as config
    with pytest.raises(config.ConfigError) as e:
        config.parse(base_config(**over), "<test>")
    assert e.value.key == key and "\n" not in str(e.value), str(e.value)


ORTHO_XML = """<scene version="3.0.0">
  <sensor type="orthographic">
    <transform name="to_world"><scale x="3" y="3"/><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
  </sensor>
  <emitter type="directional"><vector name="direction" x="0.2" y="0.1" z="-1"/></emitter>
  <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform></shape>
  <shape type="cube"><transform name="to_world"><scale value="0.5"/><translate z="0.6"/></transform></shape>
</scene>
"""


def test_an_orthographic_sensor_keeps_its_projection_or_is_refused(tmp_path):
    """[camera] resolution keeps an XML scene's orthographic sensor orthographic (every pixel's ray
    along one direction); the pose keys, which aim a pinhole camera, are refused naming the key."""
    import numpy as np
    from dsm import pipeline as pl
    from dsm.config import read as config
    xml = tmp_path / "ortho.xml"
    xml.write_text(ORTHO_XML)
    sd = pl.load_scene(pl.scene_spec({"file": str(xml)}), (64, 64))
    assert "Orthographic" in str(sd.sensor) and tuple(sd.sensor.film().size()) == (64, 48)
    gb = pl.gbuffer(sd)
    hit = np.flatnonzero(gb.hit)
    p = pl.points_np(gb.p)[hit]
    col, row = hit % gb.width, hit // gb.width
    # parallel rays straight down: a hit's x and y are linear in its pixel's column and row whatever its
    # height (fitted on the ground, the cube's top follows the same line; a pinhole's would not)
    top, ground = p[:, 2] > 0.5, p[:, 2] < 0.01
    assert top.sum() > 20 and ground.sum() > 100
    for coord, pix in ((0, col), (1, row)):
        a, b = np.polyfit(pix[ground], p[ground, coord], 1)
        assert np.abs(a * pix[top] + b - p[top, coord]).max() < 1e-4
    cfg = base_config(scene=[{"file": str(xml)}], camera={"resolution": [32, 32], "position": [0, -4, 3]})
    with pytest.raises(config.ConfigError) as e:
        pl.prepare(config.parse(cfg, "<test>"))
    assert e.value.key == "camera.position" and "orthographic" in str(e.value)
