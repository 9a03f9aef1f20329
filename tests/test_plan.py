"""The plan: cases, exact ray counts, layers only where a scheme needs them, tiles that fit memory."""
import subprocess
import sys

import numpy as np
import pytest

from conftest import base_config

CONFIGS = {
    "one_layer": dict(scheme=[{"name": "none"}, {"name": "constant"}, {"name": "slope_scaled"}]),
    "two_layers": dict(scheme=[{"name": "midpoint"}, {"name": "constant"}]),
    "back_face_layers": dict(scene=[{"builtin": "plane_box"}],
                             scheme=[{"name": "second_depth"}, {"name": "dual", "culling": "back_closed"}]),
    "stored_format": dict(map={"resolution": [32, 64], "format": ["float32", "unorm16", "ndc24"]},
                          scheme=[{"name": "constant"}, {"name": "dual"}]),
    "point_views": dict(scene=[{"builtin": "room"}], map={"resolution": 32, "view": ["dual_paraboloid", "cube"]},
                        scheme=[{"name": "adaptive"}, {"name": "midpoint"}]),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_plan_ray_counts_equal_what_the_run_casts(run_dict, name):
    from dsm.config import read as config
    from dsm.config import plan
    raw = base_config(camera={"resolution": [64, 48]}, **CONFIGS[name])
    raw.setdefault("map", {"resolution": 64})
    p = plan.make(config.parse(raw, "<test>"))
    res = run_dict(raw)
    rays = res.run["rays"]
    assert res.run["n_failed"] == 0
    assert len(res) == p.cases
    for kind, n in p.rays.items():
        assert rays[kind] == n, (kind, rays[kind], n)
    for kind, bound in p.rays_bound.items():
        assert rays[kind] <= bound, (kind, rays[kind], bound)
    assert rays["reference"] > 0
    built = [(m["scene"], m["light"], m["view"], m["resolution"], m["culling"]) for m in res.run["maps"]]
    planned = [(m.scene, m.light, m.view, m.resolution, m.culling) for m in p.maps]
    assert built == planned
    for m, pm in zip(res.run["maps"], p.maps):
        assert tuple(m["layers"]) == pm.layers
        assert m["rays"]["map_texel"] == pm.texels
        if not pm.layered:
            assert m["rays"]["map_continue"] == 0
    assert res.run["quantized_copies"] == sum(len(m.formats) for m in p.maps)
    if name == "two_layers":
        assert rays["map_continue"] > 0


def test_constant_and_none_build_nothing_more(run_dict):
    from dsm.config import read as config
    from dsm.config import plan
    raw = base_config(scheme=[{"name": "none"}, {"name": "constant", "bias": [0.01, "1 texel"]}],
                      map={"resolution": [32, 64]})
    p = plan.make(config.parse(raw, "<test>"))
    assert all(m.layers == ("z1", "shape") and not m.layered and not m.formats for m in p.maps)
    res = run_dict(raw)
    assert all(m["layers"] == ["z1", "shape"] and m["tiles"] == 1 for m in res.run["maps"])
    assert res.run["rays"]["map_continue"] == 0 and res.run["quantized_copies"] == 0
    assert "plan" in res.run and res.run["plan"]["rays"] == p.rays
    assert all(r["build_first_ms"] == r["build_ms"] > 0 for r in res.rows)   # one layer: its build is the first


@pytest.mark.slow
def test_a_small_memory_budget_tiles_the_build_with_the_same_results(run_dict):
    # per-shape culling: the layered search keeps per-texel state between its rounds, which the
    # tiles bound (without culling one fused kernel writes both layers and keeps no such state)
    raw = base_config(scene=[{"builtin": "plane_box"}], map={"resolution": 512},
                      scheme=[{"name": "dual", "culling": "back_closed"}, {"name": "constant"}])
    big = run_dict(raw, "big")
    small = run_dict({**raw, "memory": {"budget_mb": 1}}, "small")
    assert [m["tiles"] for m in big.run["maps"]] == [1, 1]             # dual's culled map, constant's
    assert small.run["maps"][0]["culling"] == "back_closed"
    assert small.run["maps"][0]["tiles"] == 512 * 512 // (1 << 16)
    for a, b in zip(big.rows, small.rows):
        assert (a["n_acne"], a["n_peterpan"]) == (b["n_acne"], b["n_peterpan"])
    m = small.run["maps"][0]
    assert m["build_peak_bytes"] < big.run["maps"][0]["build_peak_bytes"]


def test_dsm_plan_prints_before_running(tmp_path, capsys):
    from dsm import cli
    capsys.readouterr()
    rc = cli.main(["plan"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    for word in ("cases:", "rays (exact): gbuffer", "map_texel", "estimated peak memory", "cube", "layered"):
        assert word in out
    bad = tmp_path / "bad.toml"
    bad.write_text('[map]\nview = "sphere"\n[[scheme]]\nname = "none"\n[[scene]]\nbuiltin = "plane"\n')
    rc = cli.main(["plan", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and "map.view" in err and "cube" in err


def _grid_ply(path, n):
    """An n x n grid of quads (2 n^2 triangles) with a bump, as a binary little-endian PLY."""
    xs = np.linspace(-1, 1, n + 1)
    X, Y = np.meshgrid(xs, xs)
    v = np.stack([X.ravel(), Y.ravel(), 0.2 * np.exp(-(X.ravel() ** 2 + Y.ravel() ** 2) * 8)], 1).astype("<f4")
    i = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    f = np.concatenate([np.stack([i, i + 1, i + n + 2], 1), np.stack([i, i + n + 2, i + n + 1], 1)])
    rec = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rec["n"], rec["i"] = 3, f
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    path.write_bytes(head.encode() + v.tobytes() + rec.tobytes())
    return len(f)


@pytest.mark.slow
@pytest.mark.parametrize("n", [71, 224, 707])
def test_the_memory_estimate_counts_the_geometry(tmp_path, n):
    """Meshes of 1e4, 1e5 and 1e6 triangles: the plan counts their triangles from the file's header
    and its estimated peak is within 0.5x to 2x of the run's measured peak resident memory."""
    import json
    tris = _grid_ply(tmp_path / "grid.ply", n)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[experiment]\nname = "mem"\n[camera]\nresolution = [64, 64]\n[[scene]]\nfile = "grid.ply"\n'
                   'up = "z"\n[map]\nresolution = 256\n[[scheme]]\nname = "constant"\n[timing]\nrepeats = 1\n'
                   '[report]\nimages = "none"\n')
    # its own process: the peak is the process's; --no-report: the peak is taken before the report, read from run.json
    p = subprocess.run([sys.executable, "-m", "dsm", "run", str(cfg), "--out", str(tmp_path / "o"), "--no-report"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    run = json.loads((tmp_path / "o" / "run.json").read_text())
    assert list(run["plan"]["triangles"].values()) == [tris]
    est, measured = run["plan"]["peak_bytes_est"], run["timing"]["measure_peak_rss_bytes"]
    print(f"{tris} triangles: estimate {est / 2 ** 20:.0f} MB, measured peak {measured / 2 ** 20:.0f} MB")
    assert 0.5 <= est / measured <= 2.0
