"""Real meshes (data/meshes, shipped): every mesh classified, nothing NaN, one config for all scales."""
import dataclasses

import pytest

from conftest import ROOT, assert_nan_only_where_undefined



@pytest.mark.slow
def test_real_meshes_need_no_per_scene_epsilon(tmp_path):
    import dsm
    from dsm.config import read as config
    cfg = config.load(ROOT / "experiments" / "real_meshes.toml")
    cfg = dataclasses.replace(cfg, camera_resolution=(128, 128), timing_repeats=1,
                              map=dataclasses.replace(cfg.map, resolution=(512,)))
    res = dsm.run(cfg, out=tmp_path / "real", report=False)
    absent = [s for s in cfg.scenes if s.missing]              # the teapot and Sponza where not supplied
    assert {s.model or s.file.name for s in absent} <= {"mitsuba_teapot.ply", "sponza"}
    assert res.run["n_failed"] == 0 and res.run["n_skipped"] == len(absent)
    scenes = {r["scene"] for r in res.rows}
    assert len(scenes) == 7 - len(absent) >= 5
    for r in res.rows:
        assert_nan_only_where_undefined(r)
    for s in scenes:
        rs = res.where(scene=s)
        assert rs.n_receivers.min() > 2000 and rs.n_gt_lit.min() > 1000 and rs.n_gt_shadowed.min() > 20, s
        # the same texel-relative schemes work from a 0.15-unit bunny to a 556 mm Cornell box
        assert rs.where(scheme="adaptive").acne_rate.max() < 0.03, s
        assert rs.where(scheme="midpoint", params="culling=back_closed").acne_rate.max() < 0.01, s
    cbox = res.where(scene="cbox").rows[0]
    assert cbox["light"] == "0:point" and cbox["view"] == "cube"     # the default light at its luminaire
    # each mesh was loaded once for all its cases (one G-buffer per scene)
    assert set(res.run["gbuffer_ms"]) == scenes


def test_terrain_is_the_dem_in_metres():
    """The terrain's extents against the DEM's own grid (numpy, float64): north-south the arc
    of its latitude span, east-west within 0.1 % of the great-circle distance along its centre
    latitude; heights the DEM's; two triangles per cell, all facing up."""
    import math

    import numpy as np
    from matplotlib import cbook

    from dsm.scenes import terrain
    with np.load(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)) as d:
        z, dx, dy = d["elevation"].astype(float), float(d["dx"]), float(d["dy"])
        lat0 = math.radians((float(d["ymin"]) + float(d["ymax"])) / 2)
    rows, cols = z.shape
    v, f = terrain.mesh()
    r = 6371008.8
    assert len(f) == 2 * (rows - 1) * (cols - 1) == 275772 and len(v) == rows * cols
    ns = np.ptp(v[:, 1])
    assert abs(ns - r * math.radians((rows - 1) * dy)) < 1e-6 * ns
    half = math.radians((cols - 1) * dx) / 2           # haversine between the row's two ends
    great_circle = 2 * r * math.asin(math.cos(lat0) * math.sin(half))
    assert abs(np.ptp(v[:, 0]) - great_circle) < 1e-3 * great_circle
    assert (v[:, 2].min(), v[:, 2].max()) == (z.min(), z.max()) == (236.0, 1076.0)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert (n[:, 2] > 0).all()
    v2, f2 = terrain.mesh(2)                           # every second sample
    assert len(v2) == -(-rows // 2) * -(-cols // 2) and np.ptp(v2[:, 2]) <= np.ptp(v[:, 2])
