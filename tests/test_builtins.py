"""The occluder built-ins (occluder_plate, occluder_box, occluder_mesh: dsm grad's scenes) in a plain
dsm run, against a float64 numpy count of the shadow a camera straight above sees; the mesh's placement
against the file's own vertices read with numpy."""
import csv
import math

import numpy as np
import pytest

from conftest import ROOT, cli_run, write_toml
from dsm.core.types import ConfigError

HC, FOV, N = 3.0, 40.0, 40          # the camera's height, horizontal field of view (degrees), pixels per side
TILT = 30.0                         # the light's tilt from the vertical toward +x, degrees
# the camera off the occluder's axis: a pixel centre on a diagonal of the symmetric scene would meet the
# triangles' shared edges exactly (a ray there may pass between them: measured, 3 pixels of 1600)
CX, CY = 0.013, 0.029


def _slab_hit(o, d, lo, hi, t_max):
    """Whether rays o + t d (t in (0, t_max)) cross the box [lo, hi] (float64; a flat box is a plate)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    near = np.nanmax(np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1)), axis=-1)
    far = np.nanmin(np.where(np.isnan(t1), np.inf, np.maximum(t0, t1)), axis=-1)
    return (near <= far) & (far > 0) & (near < t_max)


def _expected_shadowed(size, height, top):
    """Pixels of the camera straight above that see the ground in the shadow of the box (size x size,
    from height to top) under the tilted light: numpy float64, pinhole rays through pixel centres."""
    c = ((np.arange(N) + 0.5) / N * 2.0 - 1.0) * math.tan(math.radians(FOV / 2)) * HC
    gx, gy = np.meshgrid(c + CX, c + CY)
    ground = np.stack([gx, gy, np.zeros_like(gx)], -1).reshape(-1, 3)
    lo, hi = np.array([-size / 2, -size / 2, height]), np.array([size / 2, size / 2, top])
    cam = np.array([CX, CY, HC])
    hidden = _slab_hit(cam, ground - cam, lo, hi, 1.0)
    to_light = np.array([-math.sin(math.radians(TILT)), 0.0, math.cos(math.radians(TILT))])
    shadowed = _slab_hit(ground, to_light, lo, hi, np.inf)
    return int((shadowed & ~hidden).sum())


def _config(scenes) -> dict:
    """A config of ``scenes`` seen by the camera straight above, under the tilted directional light."""
    t = math.radians(TILT)
    return {"camera": {"resolution": [N, N], "position": [CX, CY, HC], "target": [CX, CY, 0.0], "up": [0.0, 1.0, 0.0],
                       "fov": FOV},
            "scene": scenes, "light": [{"type": "directional", "direction": [math.sin(t), 0.0, -math.cos(t)]}],
            "map": {"resolution": 64}, "scheme": [{"name": "none"}], "report": {"images": "none"}}


def test_the_occluder_plates_exact_shadow_is_the_numpy_count():
    """The plate built-in through the kit's stages (load, G-buffer, receivers, V*): the shadowed receivers
    are those numpy finds."""
    from dsm import pipeline
    from dsm.config import read
    cfg = read.parse(_config([{"builtin": "occluder_plate", "size": 0.5, "height": 0.5}]), "<occ>")
    sd = pipeline.load_scene(cfg.scenes[0], (N, N), cfg.camera)
    setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), cfg.lights[0], "0")
    assert len(setup.pixels) == N * N
    assert int((~setup.v_star).sum()) == _expected_shadowed(0.5, 0.5, 0.5) == _expected_shadowed(0.5 + 1e-6, 0.5, 0.5)


def _run(tmp_path, capsys, scenes):
    cfg = write_toml(tmp_path / "occ.toml", _config(scenes))
    rc, err = cli_run(capsys, "run", cfg, "--out", tmp_path / "out")
    assert rc == 0, err
    return list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))


@pytest.mark.slow
def test_the_occluder_plate_and_box_cast_the_shadow_a_numpy_count_predicts_in_a_dsm_run(tmp_path, capsys):
    """Exact visibility (the run's V*) of the plate and the box built-ins: every pixel a receiver (the ground
    and the occluder's top face the light), the shadowed ones those numpy finds, to the pixel."""
    rows = _run(tmp_path, capsys, [{"builtin": "occluder_plate", "size": 0.5, "height": 0.5},
                                   {"builtin": "occluder_box", "size": 0.6, "height": 0.3, "box_height": 0.4}])
    want = {"occluder_plate": _expected_shadowed(0.5, 0.5, 0.5),
            "occluder_box(size=0.6,height=0.3,box_height=0.4)": _expected_shadowed(0.6, 0.3, 0.7)}
    # the expected counts hold for the occluders grown or shrunk by 1e-6: no pixel sits on an edge
    assert want == {"occluder_plate": _expected_shadowed(0.5 * (1 + 1e-6), 0.5, 0.5),
                    "occluder_box(size=0.6,height=0.3,box_height=0.4)": _expected_shadowed(0.6 * (1 - 1e-6), 0.3, 0.7)}
    assert min(want.values()) > 40
    assert {r["scene"]: int(r["n_gt_shadowed"]) for r in rows} == want
    assert [int(r["n_receivers"]) for r in rows] == [N * N, N * N]


def test_the_occluder_mesh_is_the_file_scaled_to_its_size_on_its_height(tmp_path):
    """occluder_mesh: the file's vertices (read here with numpy) scaled so the largest extent is size,
    centred in x and y, the lowest point at height; its file relative to the config; bad files refused."""
    from dsm.scenes.builtins import builtin_geometry
    from dsm.scenes.ply import ply_positions
    from dsm.scenes.spec import parse_scene
    bunny = ROOT / "data/meshes/mitsuba_bunny.ply"
    (spec,) = parse_scene({"builtin": "occluder_mesh", "mesh": "meshes/mitsuba_bunny.ply", "size": 0.4,
                           "height": 0.3}, "g.toml", "scene[0]", ROOT / "data")
    assert spec.params.mesh == str(bunny)
    shapes, _, _ = builtin_geometry(spec.builtin, spec.params)
    assert list(shapes) == ["ground", "occluder"]
    raw = ply_positions(bunny).astype(np.float32).astype(np.float64)
    lo, hi = raw.min(0), raw.max(0)
    want = (raw - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]) * (0.4 / np.max(hi - lo)) + [0.0, 0.0, 0.3]
    v = shapes["occluder"][0]
    assert np.abs(v - want).max() < 1e-12
    assert np.ptp(v, axis=0).max() == pytest.approx(0.4) and v[:, 2].min() == pytest.approx(0.3)
    (default,) = parse_scene({"builtin": "occluder_mesh"}, "g.toml", "scene[0]", tmp_path)
    assert np.array_equal(builtin_geometry(default.builtin, default.params)[0]["occluder"][1],
                          shapes["occluder"][1])           # the kit's bunny when no mesh is named
    (tmp_path / "empty.ply").write_text("")
    for mesh, words in (("nowhere.ply", "scene[0].mesh: no such file"), ("empty.ply", "scene[0].mesh: "),
                        ("a.stl", "unsupported file type '.stl' (valid: .ply, .obj)"), (3, "expected a path string")):
        with pytest.raises(ConfigError) as e:
            parse_scene({"builtin": "occluder_mesh", "mesh": mesh}, "g.toml", "scene[0]", tmp_path)
        assert words in str(e.value) and "\n" not in str(e.value), str(e.value)
