"""A spot light's virtual shadow map (dsm.maps.virtual_punctual): a plane's level histogram derived from
each receiver's camera depth and its distance to the light by EEVEE's punctual rule (written out here
in float64), each level's pages against the whole perspective map of that level's resolution, a run's
columns and the config's refusals. Expected values: the rule in numpy float64 and the kit's single
perspective map."""

import math
from dataclasses import replace

import numpy as np
import pytest

from conftest import base_config

# low over the plane's far end, facing the camera: near receivers far from the light, far ones near it
SPOT = {"position": (0.0, 2.5, 0.8), "target": (0.0, -0.5, 0.0), "cutoff": 40.0}
SMALL = {"resolution": 2048, "page_size": 64}      # 32 pages a side at level 0: levels 0 to 5 halve whole pages


def _spec(**over):
    from dsm.core.types import VIRTUAL_PRESETS
    return replace(VIRTUAL_PRESETS["eevee_punctual"], **{**SMALL, **over})


def _plane(res=96):
    import dsm.pipeline as pl
    from dsm.core.types import CameraSpec, LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane", "tilt": 0.0}), (res, res),
                       CameraSpec(position=(0.0, -2.3, 0.35), target=(0.0, 1.5, 0.0)))
    setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("spot", **SPOT), "spot")
    return pl, sd, setup


def _derived_levels(spec, cam, light_pos, axis, pts):
    """EEVEE's punctual rule in float64: (x = log2(footprint / level-0 texel radius), level = floor(clamp x))."""
    from dsm.maps.views import light_frame
    ex, ey, ez = (np.asarray(a, float) for a in light_frame(axis))
    q = pts - np.asarray(light_pos, float)
    largest = np.max(np.abs(np.stack([q @ ex, q @ ey, q @ ez], 1)), axis=1)     # the light's largest-axis distance
    z_cam = (pts - cam.origin) @ cam.forward                                       # the camera's view depth
    pixel = math.hypot(2 * cam.tan_x / cam.width, 2 * cam.tan_y / cam.height) * 2.0 ** spec.lod_bias
    texel = 2.0 * math.sqrt(2.0) * math.tan(math.radians(SPOT["cutoff"])) / spec.resolution
    world = spec.lod_min if spec.lod_min > 0 else 0.0          # metres: a scene unit here (unit_cm 100)
    on_plane = -spec.lod_min if spec.lod_min < 0 else 0.0
    x = np.log2(np.maximum(np.maximum(pixel * z_cam, world) / largest, on_plane) / texel)
    return x, np.floor(np.clip(x, spec.first_level, spec.last_level))


@pytest.mark.parametrize("lod_bias", [0.0, -1.0])
def test_plane_level_histogram_follows_from_each_receivers_distances(lod_bias):
    """A spot over a plane seen at a grazing angle: each receiver's level is the finest whose texel
    radius (level 0's, 2 sqrt 2 tan(cutoff) / R on the light's unit plane, doubled per level) covers
    its camera pixel's radius times 2^lod_bias times its view depth, over its largest-axis distance to
    the light; the kit's histogram equals the one derived here in float64 (receivers within 1e-4 of a
    level boundary left out, at most 1 %), and every receiver's own texel is on a tagged page."""
    import drjit as dr
    import mitsuba as mi
    from dsm.scenes.camera import Camera
    from dsm.truth.virtual import level_histogram
    pl, sd, setup = _plane()
    spec = _spec(lod_bias=lod_bias)
    pts = pl.points_np(setup.p)
    view = pl.make_view(setup.light, spec.resolution, pts, sd.bbox, "perspective", spec, sd.sensor, sd.scale)
    rx = pl.receivers(view, setup, sd.diagonal)
    faces = np.asarray(rx.face.numpy(), int)
    axis = np.subtract(SPOT["target"], SPOT["position"])
    x, want = _derived_levels(spec, Camera.from_sensor(sd.sensor), SPOT["position"], axis, pts)
    ok = np.abs(x - np.round(x)) > 1e-4
    assert ok.mean() > 0.99 and len(pts) > 1000
    levels, counts = np.unique(want[ok], return_counts=True)
    assert len(levels) >= 3                      # the grazing view spans several levels
    assert level_histogram(view, faces[ok]) == {int(a): int(b) for a, b in zip(levels, counts)}
    assert sum(level_histogram(view, faces).values()) == len(pts)
    i, j = mi.Int32(dr.floor(rx.u_map)), mi.Int32(dr.floor(rx.v_map))
    _, absent = view.texel_index(rx.face, i, j)
    assert not np.any(absent.numpy())
    # a receiver's texel (world) is its level's: 2^level times level 0's at the same point
    assert np.allclose(rx.texel_world.numpy(), _level0_texel(view, pts) * 2.0 ** view.levels[faces], rtol=1e-5)


def _level0_texel(view, pts):
    """A planar texel's world footprint at level 0 (float64): step z (1 + a^2 + b^2)^(-1/4), step = 2 T / R."""
    ex, ey, ez = view.axes_np
    q = pts - view.origin_np
    x, y, z = q @ ex, q @ ey, q @ ez
    return 2.0 * view.tan_half / view.resolution * z * (1.0 + (x * x + y * y) / (z * z)) ** -0.25


LEVEL0_TEXEL = 2.0 * math.sqrt(2.0) * math.tan(math.radians(40.0)) / SMALL["resolution"]    # on the unit plane


@pytest.mark.parametrize("lod_min", [-LEVEL0_TEXEL * 2.0 ** 4.5, 0.03])
def test_lod_min_floors_the_footprint_in_the_world_or_on_the_light_plane(lod_min):
    """lod_min > 0 (metres) floors the camera footprint in the world before the division by the
    light's distance, < 0 floors it on the light's unit plane after; with lod_bias -3 the floor is
    above every receiver's own footprint, so the floor alone sets the levels (derived here)."""
    from dsm.maps.virtual_punctual import VirtualSpotView
    from dsm.scenes.camera import Camera
    pl, sd, setup = _plane(48)
    pts = pl.points_np(setup.p)
    cam = Camera.from_sensor(sd.sensor)
    axis = np.subtract(SPOT["target"], SPOT["position"])
    spec = _spec(lod_bias=-3.0, lod_min=lod_min)
    view = VirtualSpotView(SPOT["position"], axis, SPOT["cutoff"], spec, cam, pts, sd.bbox)
    got = view.levels[np.asarray(pl.receivers(view, setup, sd.diagonal).face.numpy(), int)]
    x, want = _derived_levels(spec, cam, SPOT["position"], axis, pts)
    x_free, _ = _derived_levels(_spec(lod_bias=-3.0), cam, SPOT["position"], axis, pts)
    assert np.all(x > x_free + 0.5)                 # the floor decides every receiver's level
    ok = np.abs(x - np.round(x)) > 1e-4
    assert ok.mean() > 0.99 and np.array_equal(got[ok], want[ok])
    assert len(np.unique(want)) >= (1 if lod_min < 0 else 2)


@pytest.mark.slow
@pytest.mark.parametrize("level", [1, 3])
def test_a_level_s_pages_are_the_whole_perspective_map_of_its_resolution(level):
    """Every receiver in one level (first_level = last_level): the page-list build's z1 and shape at its
    texels equal the whole perspective map's of resolution R / 2^level, and every scheme on spot views
    gives the same V with the nearest lookup and with PCF."""
    import drjit as dr
    import mitsuba as mi
    from dsm.maps.views import PerspectiveView
    from dsm.maps.virtual_punctual import VirtualSpotView
    from dsm.scenes.camera import Camera
    import dsm.pipeline as pl
    from dsm.core.types import LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (64, 64), None)
    setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("spot", **SPOT), "spot")
    spec = _spec(first_level=level, last_level=level, border=0.5)
    axis = np.subtract(SPOT["target"], SPOT["position"])
    pts = pl.points_np(setup.p)
    vview = VirtualSpotView(SPOT["position"], axis, SPOT["cutoff"], spec, Camera.from_sensor(sd.sensor), pts, sd.bbox)
    R = spec.resolution >> level
    pview = PerspectiveView(SPOT["position"], axis, SPOT["cutoff"], sd.bbox, R)
    specs = [pl.scheme_spec({"name": "constant", "bias": b}) for b in (0.0, "1 texel")]
    specs += [pl.scheme_spec(s) for s in ({"name": "slope_scaled"}, {"name": "normal_offset"},
                                           {"name": "receiver_plane"})]
    needs = pl.needs_of(specs)
    mv, mp = pl.build_map(sd.scene, vview, needs), pl.build_map(sd.scene, pview, needs)
    face, cu, cv = vview.texel_coords(dr.arange(mi.UInt32, vview.n_texels))
    at = (np.asarray(cv.numpy()) - 0.5).astype(int) * R + (np.asarray(cu.numpy()) - 0.5).astype(int)
    assert not np.any(face.numpy()) and len(np.unique(at)) == vview.n_texels < R * R
    for layer in ("z1", "slope", "shape"):
        assert np.array_equal(getattr(mv, layer).numpy(), getattr(mp, layer).numpy()[at]), layer
    rv, rp = pl.receivers(vview, setup, sd.diagonal), pl.receivers(pview, setup, sd.diagonal)
    for s in specs:
        for filt in ("nearest", "pcf_bilinear"):
            a, _ = pl.visibility(s, rv, mv, filt)
            b, _ = pl.visibility(s, rp, mp, filt)
            assert np.array_equal(a.numpy(), b.numpy()), (s.name, filt)


def test_a_run_reports_pages_levels_and_costs(run_dict):
    """A spot's virtual map in a run: its cases carry the layout, the vsm_* columns (pages tagged =
    built, physical texels = pages x page_size^2 = rays), the level histogram summing to the receivers,
    map_bytes = texels x 4 and page_table_bytes = 4 x the virtual pages of every level."""
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                      light=[{"type": "spot", "position": list(SPOT["position"]), "target": list(SPOT["target"]),
                              "cutoff": SPOT["cutoff"]}],
                      map={"virtual": {"preset": "eevee_punctual", **SMALL, "lod_bias": -2.0}},
                      scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}])
    res = run_dict(cfg, "spot")
    assert len(res.rows) == 2
    entries = sum((32 >> k) ** 2 for k in range(6))
    for r in res.rows:
        assert r["view"] == "perspective" and r["cascade_layout"].startswith("vsm eevee_punctual")
        assert r["vsm_pages_tagged"] == r["vsm_pages_built"] > 0
        assert r["vsm_memory_texels"] == r["vsm_pages_tagged"] * 64 ** 2 == r["vsm_rays"] == r["map_rays"]
        hist = dict(w.split(":") for w in r["vsm_level_histogram"].split())
        assert sum(map(int, hist.values())) == r["n_receivers"] > 0 and len(hist) >= 2
        assert r["map_bytes"] == 4 * r["vsm_memory_texels"] and r["page_table_bytes"] == 4 * entries


@pytest.mark.parametrize("table,key", [
    ({"preset": "eevee_punctual", "first_level": -1}, "map.virtual.first_level"),
    ({"preset": "eevee_punctual", "last_level": 6}, "map.virtual.last_level"),
    ({"preset": "eevee_punctual", "lod_min": "big"}, "map.virtual.lod_min"),
])
def test_bad_punctual_keys_are_config_errors_naming_the_key(table, key):
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    spot = {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0]}
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(light=[spot], map={"virtual": table}), "t.toml")
    assert e.value.key == key and "t.toml" in str(e.value)


def test_punctual_without_a_spot_light_is_a_config_error_and_each_light_gets_its_own():
    """eevee_punctual needs a spot light (ue5 a directional one); with both, the plan gives the sun
    ue5's clipmap and the spot eevee_punctual's page table, nothing else."""
    from dsm.config import plan, read as config
    from dsm.core.types import ConfigError
    sun = {"type": "directional", "direction": [0, 0, -1]}
    spot = {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0]}
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(light=[sun], map={"virtual": {"preset": "eevee_punctual"}}), "t.toml")
    assert e.value.key == "map.virtual" and "spot" in str(e.value)
    cfg = config.parse(base_config(light=[sun, spot], map={"virtual": {"preset": ["ue5", "eevee_punctual"]}}),
                       "t.toml")
    got = sorted((m.light, m.view, m.cascade.preset) for m in plan.make(cfg).maps)
    assert [(v, p) for _, v, p in got] == [("orthographic", "ue5"), ("perspective", "eevee_punctual")]
