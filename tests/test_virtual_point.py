"""A point light's virtual shadow map (dsm.maps.virtual_punctual.VirtualCubeView) in a box room: each
receiver reads the cube face its direction's major axis selects and the level EEVEE's punctual rule
gives its distances (both derived here in numpy float64), one level's pages against the whole cube
map of that level's resolution, and a run's columns. Expected values: the rule written out here and
the kit's single cube map."""

import math
from dataclasses import replace

import numpy as np
import pytest

from conftest import base_config

LIGHT = (0.3, -0.2, 1.1)
SMALL = {"resolution": 2048, "page_size": 64}


def _spec(**over):
    from dsm.core.types import VIRTUAL_PRESETS
    return replace(VIRTUAL_PRESETS["eevee_punctual"], **{**SMALL, **over})


def _room(res=96):
    import dsm.pipeline as pl
    from dsm.core.types import LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "room"}), (res, res), None)
    setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("point", position=LIGHT), "point")
    return pl, sd, setup


def _derived(spec, cam, pts):
    """(cube face, x = log2(footprint / level-0 texel radius), level, how far from a face tie) in float64."""
    q = pts - np.asarray(LIGHT, float)
    a = np.abs(q)
    axis = np.where((a[:, 0] >= a[:, 1]) & (a[:, 0] >= a[:, 2]), 0, np.where(a[:, 1] >= a[:, 2], 1, 2))
    face = 2 * axis + (q[np.arange(len(q)), axis] < 0)
    largest = a.max(axis=1)
    z_cam = (pts - cam.origin) @ cam.forward
    pixel = math.hypot(2 * cam.tan_x / cam.width, 2 * cam.tan_y / cam.height) * 2.0 ** spec.lod_bias
    texel = 2.0 * math.sqrt(2.0) / spec.resolution              # EEVEE's: a cube face's half width is 1
    x = np.log2(pixel * z_cam / largest / texel)
    tie = (largest - np.sort(a, axis=1)[:, 1]) / largest         # 0 on a cube edge
    return face, x, np.floor(np.clip(x, spec.first_level, spec.last_level)), tie


@pytest.mark.parametrize("lod_bias", [0.0, -1.5])
def test_each_receiver_reads_its_directions_face_and_its_distances_level(lod_bias):
    """Every receiver of the room: its cube face (the major axis of its direction from the light, ties
    to x, then y) and its level (EEVEE's punctual rule) equal the ones derived in float64, receivers
    within 1e-4 of a level boundary or 1e-6 of a cube edge left out (at most 1 %); the histogram over
    (face, level) equal, several faces and levels met; each receiver's own texel on a tagged page."""
    import drjit as dr
    import mitsuba as mi
    from dsm.scenes.camera import Camera
    pl, sd, setup = _room()
    spec = _spec(lod_bias=lod_bias)
    pts = pl.points_np(setup.p)
    view = pl.make_view(setup.light, spec.resolution, pts, sd.bbox, "cube", spec, sd.sensor, sd.scale)
    rx = pl.receivers(view, setup, sd.diagonal)
    faces = np.asarray(rx.face.numpy(), int)
    cube, level = faces // len(view.levels), view.level_of_face(faces)
    want_face, x, want_level, tie = _derived(spec, Camera.from_sensor(sd.sensor), pts)
    ok = (np.abs(x - np.round(x)) > 1e-4) & (tie > 1e-6)
    assert ok.mean() > 0.99 and len(pts) > 1000
    assert np.array_equal(cube[ok], want_face[ok]) and np.array_equal(level[ok], want_level[ok])
    pairs = lambda f, l: dict(zip(*np.unique(f * 100 + l, return_counts=True)))
    assert pairs(cube[ok], level[ok]) == pairs(want_face[ok], want_level[ok].astype(int))
    assert len(np.unique(want_face[ok])) >= 3 and len(np.unique(want_level[ok])) >= 2
    i, j = mi.Int32(dr.floor(rx.u_map)), mi.Int32(dr.floor(rx.v_map))
    assert not np.any(view.texel_index(rx.face, i, j)[1].numpy())


@pytest.mark.slow
@pytest.mark.parametrize("level", [2, 4])
def test_a_level_s_pages_are_the_whole_cube_map_of_its_resolution(level):
    """Every receiver in one level: the page-list build's z1, slope and shape at its texels equal the
    whole cube map's of resolution R / 2^level (face by face), and five schemes give the same V with
    the nearest lookup and PCF, in float32 and ndc24."""
    import drjit as dr
    import mitsuba as mi
    from dsm.maps.views import CubeView
    from dsm.maps.virtual_punctual import VirtualCubeView
    from dsm.scenes.camera import Camera
    pl, sd, setup = _room(64)
    spec = _spec(first_level=level, last_level=level, border=0.5)
    pts = pl.points_np(setup.p)
    vview = VirtualCubeView(LIGHT, spec, Camera.from_sensor(sd.sensor), pts, sd.bbox)
    R = spec.resolution >> level
    cview = CubeView(LIGHT, sd.bbox, R)
    specs = [pl.scheme_spec({"name": "constant", "bias": b}) for b in (0.0, "1 texel")]
    specs += [pl.scheme_spec(s) for s in ({"name": "slope_scaled"}, {"name": "normal_offset"},
                                           {"name": "receiver_plane"})]
    needs = pl.needs_of(specs)
    mv, mc = pl.build_map(sd.scene, vview, needs), pl.build_map(sd.scene, cview, needs)
    face, cu, cv = vview.texel_coords(dr.arange(mi.UInt32, vview.n_texels))
    at = (np.asarray(face.numpy(), int) * R + (np.asarray(cv.numpy()) - 0.5).astype(int)) * R \
        + (np.asarray(cu.numpy()) - 0.5).astype(int)
    assert len(np.unique(at)) == vview.n_texels <= 6 * R * R and len(np.unique(face.numpy())) >= 3
    for layer in ("z1", "slope", "shape"):
        assert np.array_equal(getattr(mv, layer).numpy(), getattr(mc, layer).numpy()[at]), layer
    for fmt in ("float32", "ndc24"):
        sv, sc = pl.store(mv, fmt), pl.store(mc, fmt)
        rv, rc = pl.receivers(sv.view, setup, sd.diagonal), pl.receivers(sc.view, setup, sd.diagonal)
        for s in specs:
            for filt in ("nearest", "pcf_bilinear"):
                a, _ = pl.visibility(s, rv, sv, filt)
                b, _ = pl.visibility(s, rc, sc, filt)
                assert np.array_equal(a.numpy(), b.numpy()), (s.name, filt, fmt)


def test_a_run_reports_pages_levels_and_costs(run_dict):
    """A point light's virtual map in a run (map.view cube): the vsm_* columns, the histogram summing to
    the receivers, map_bytes = texels x 4 and page_table_bytes = 4 x six faces' virtual pages of every level."""
    cfg = base_config(scene=[{"builtin": "room"}], camera={"resolution": [48, 48]},
                      map={"view": "cube", "virtual": {"preset": "eevee_punctual", **SMALL}},
                      scheme=[{"name": "constant", "bias": "1 texel"}])
    res = run_dict(cfg, "point")
    assert len(res.rows) == 1
    r = res.rows[0]
    assert r["view"] == "cube" and r["cascade_layout"].startswith("vsm eevee_punctual")
    assert r["vsm_pages_tagged"] == r["vsm_pages_built"] > 0
    assert r["vsm_memory_texels"] == r["vsm_pages_tagged"] * 64 ** 2 == r["vsm_rays"] == r["map_rays"]
    hist = dict(w.split(":") for w in r["vsm_level_histogram"].split())
    assert sum(map(int, hist.values())) == r["n_receivers"] > 0
    assert r["map_bytes"] == 4 * r["vsm_memory_texels"]
    assert r["page_table_bytes"] == 4 * 6 * sum((32 >> k) ** 2 for k in range(6))


def test_a_point_light_gets_a_virtual_map_only_in_its_cube_view():
    """eevee_punctual on a point light replaces its cube view; a config whose point light has no cube
    view gets no virtual map and is refused before any work, naming map.virtual and the cube view."""
    from dsm.config import plan, read as config
    from dsm.core.types import ConfigError
    point = {"type": "point", "position": [0, 0, 2]}
    cfg = config.parse(base_config(light=[point], map={"view": ["cube", "dual_paraboloid"],
                                                       "virtual": {"preset": "eevee_punctual"}}), "t.toml")
    got = sorted((m.view, m.cascade.preset if m.cascade is not None else "") for m in plan.make(cfg).maps)
    assert got == [("cube", "eevee_punctual"), ("dual_paraboloid", "")]
    cfg = config.parse(base_config(light=[point], map={"virtual": {"preset": "eevee_punctual"}}), "t.toml")
    with pytest.raises(ConfigError) as e:
        plan.make(cfg)
    assert e.value.key == "map.virtual" and "cube" in str(e.value) and "t.toml" in str(e.value)
