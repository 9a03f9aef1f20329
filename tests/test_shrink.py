"""Caster shrinking ([map] shrink): welded, area-weighted vertex normals; a closed mesh's shrunk depth."""

import numpy as np

import pytest

import dsm.pipeline as pl
from conftest import cli_run as _cli, one_line as _one_line, base_config, toml_text
from dsm.config import read as config
from dsm.config.read import ConfigError
from dsm.core.types import LightSpec
from dsm.maps import shrink

R, D = 1.0, 0.1


def split_octahedron(r):
    """A closed octahedron |x| + |y| + |z| = r wound outward, each triangle with its own three vertices."""
    verts, faces = [], []
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                tri = [[sx * r, 0, 0], [0, sy * r, 0], [0, 0, sz * r]]
                if sx * sy * sz < 0:
                    tri = tri[::-1]                  # outward: (b - a) x (c - a) along (sx, sy, sz)
                faces.append([len(verts), len(verts) + 1, len(verts) + 2])
                verts += tri
    return np.array(verts, float), np.array(faces)


def test_welded_normals_are_area_weighted_over_split_vertices():
    # two triangles meeting at the origin, stored apart: areas 2 (normal +z) and 0.5 (normal +x)
    verts = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    n = shrink.welded_normals(verts, faces)
    want = np.array([0.5, 0.0, 2.0]) / np.hypot(0.5, 2.0)       # 2 * area * normal, summed, normalized
    assert np.allclose(n[0], want) and np.allclose(n[3], want)
    assert np.allclose(n[1], [0, 0, 1]) and np.allclose(n[5], [1, 0, 0])


def test_octahedron_normals_are_radial():
    v, f = split_octahedron(R)
    n = shrink.welded_normals(v, f)
    assert np.allclose(n, v / R)                   # 4 equal triangles around each vertex, symmetric
    moved = shrink.shrunk_vertices(v, f, D)
    assert np.allclose(np.abs(moved).sum(1), R - D)     # the octahedron of size R - D, uncracked


@pytest.fixture(scope="module")
def octa():
    import mitsuba as mi
    from dsm.scenes.camera import look_at_sensor
    from dsm.scenes.geometry import make_mesh
    v, f = split_octahedron(R)
    scene = mi.load_dict({"type": "scene", "octa": make_mesh("octa", v, f),
                          "sensor": look_at_sensor((0, -0.5, 5), (0, 0, 0), (0, 1, 0), 40.0, 96, 96)}, optimize=False)
    return pl.scene_from_mitsuba(scene)


def test_shrunk_octahedron_is_d_deeper_from_above(octa):
    """From a light straight above, the top surface z = R - |x| - |y| drops to R - D - |x| - |y|: every
    texel inside the shrunk footprint is D deeper (face normals would give D sqrt(3))."""
    sd = octa
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=(0.0, 0.0, -1.0)), "sun")
    view = pl.make_view(setup.light, 128, pl.points_np(setup.p), sd.bbox)
    z0 = pl.build_map(sd.scene, view, ()).z1.numpy()
    z1 = pl.build_map(pl.shrunk_scene(sd.scene, D), view, ()).z1.numpy()
    # texel centres in world: the receivers' own texels, where the surface is known
    rx = pl.receivers(view, setup, sd.diagonal)
    p = pl.points_np(setup.p)
    R_map = view.resolution
    idx = np.floor(rx.v_map.numpy()).astype(int) * R_map + np.floor(rx.u_map.numpy()).astype(int)
    top = (p[:, 2] > 0) & (np.abs(p[:, 0]) + np.abs(p[:, 1]) < R - D - 0.1)
    assert top.sum() > 200
    dz = z1[idx[top]] - z0[idx[top]]
    assert np.allclose(dz, D, atol=2e-5)


@pytest.mark.slow
def test_shrink_is_planned_and_moves_only_the_casters(run_dict):
    cfg = base_config(scene=[{"builtin": "plane_box"}], scheme=[{"name": "none"}], map={"resolution": 128})
    plain = run_dict(cfg, "plain").rows[0]
    cfg["map"] = {"resolution": 128, "shrink": 0.01}
    res = run_dict(cfg, "shrunk")
    row = res.rows[0]
    assert row["n_receivers"] == plain["n_receivers"] and row["n_gt_lit"] == plain["n_gt_lit"]   # reference as is
    assert row["n_acne"] < plain["n_acne"]       # the ground and box moved away from their own receivers
    assert res.run["plan"]["shrink"] == 0.01 and "shrink" not in run_dict(base_config(), "bare").run["plan"]


@pytest.mark.parametrize("value", [-0.1, "1 texel", [0.1, 0.2]])
def test_bad_shrink_is_a_config_error(value):
    import dsm
    with pytest.raises(ConfigError) as e:
        dsm.parse_config(base_config(map={"resolution": 64, "shrink": value}), "<t>")
    assert e.value.key == "map.shrink"


def test_shrink_of_a_scene_with_non_mesh_shapes_is_refused_before_work(tmp_path):
    """Mitsuba's analytic sphere has no vertices to move."""
    from conftest import ROOT
    xml = (ROOT / "tests" / "data" / "spot_scene.xml").read_text().replace('<shape type="cube" id="box">',
                                                                          '<shape type="sphere" id="ball">')
    path = tmp_path / "ball.xml"
    path.write_text(xml)
    cfg = base_config(scene=[{"file": str(path)}], map={"resolution": 32, "shrink": 0.01})
    with pytest.raises(ConfigError) as e:
        pl.prepare(cfg)
    assert e.value.key == "map.shrink" and "ball" in str(e.value) and "\n" not in str(e.value)


def test_a_shrink_that_turns_a_closed_caster_inside_out_is_a_config_error(tmp_path, capsys):
    """plane_box's box is 1 x 1 x 1 (a closed cube): shrunk by 0.5 or more its faces cross and it
    comes out inside out, a larger caster facing in (the watertight bunny shrunk by 5 shadowed
    92 % of the lit receivers, exit 0). The ground is open: it only moves down. Just below half
    it still runs."""
    from dsm.scenes import load as scenes
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [16, 16]},
                      map={"resolution": 16, "shrink": 0.5})
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "run", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), "map.shrink", "'box'", "inside out", "0.5")
    assert not (tmp_path / "out" / "metrics.csv").exists()
    scenes.check(config.parse(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [16, 16]},
                                          map={"resolution": 16, "shrink": 0.49}), "<test>"))
