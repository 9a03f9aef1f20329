"""Virtual shadow maps (dsm.maps.virtual): a level's texel against the pixel footprint that chose
it, a plane's level histogram derived from its receivers' distances, one level with every page
tagged against the single orthographic map, the page-list build against the whole map, the run's
columns and the config's refusals. Expected values: the engines' rules written out here in float64
(numpy) and the kit's single orthographic map."""

import math

import numpy as np
import pytest

from conftest import base_config

DOWN = (0.0, 0.0, -1.0)
SLANT = (0.2, -0.5, -0.6)


def _camera(width=64, fov_deg=40.0):
    from dsm.scenes.camera import Camera
    tx = math.tan(math.radians(fov_deg) / 2)
    return Camera(np.zeros(3), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0]),
                  tx, tx, 1e-2, 1e4, width, width)


def _points(n=4000, seed=3, dmin=0.05, dmax=400.0):
    """Points in the camera's view cone at log-uniform distances (float32 values, held as float64)."""
    rng = np.random.default_rng(seed)
    d = np.exp(rng.uniform(math.log(dmin), math.log(dmax), n))
    dirs = np.stack([rng.uniform(-0.3, 0.3, n), np.ones(n), rng.uniform(-0.3, 0.3, n)], 1)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return (dirs * d[:, None]).astype(np.float32).astype(np.float64)


def _levels(view, pts):
    import mitsuba as mi
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    return view.levels[np.asarray(view.face_of(p).numpy(), int)], np.asarray(view.texel_world(p).numpy(), float)


def _off_boundary(x, eps=1e-4):
    """Values at least ``eps`` from an integer (a float32 kernel may round the other way within it)."""
    return np.abs(x - np.round(x)) > eps


def test_ue5_level_texel_is_the_pixel_footprint_times_two_to_the_lod_bias():
    """UE5's rule: the finest level whose texel exceeds the camera pixel's footprint 2 d tan(fov/2) / W
    times 2^lod_bias (level l is 2^(l+3) cm wide over R texels), never finer than the level whose
    radius 2^(l+1) cm covers d; every receiver's texel (its Receiver's texel_world too) in (1, 2] x that."""
    import mitsuba as mi
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.maps.virtual import VirtualView
    from dsm.maps.receiver import Receiver
    spec = VIRTUAL_PRESETS["ue5"]
    cam, pts = _camera(), _points()
    view = VirtualView(DOWN, spec, cam, pts[:50], (pts.min(0), pts.max(0)))
    lvl, texel = _levels(view, pts)
    d = np.linalg.norm(pts, axis=1)
    f = 2.0 * d * cam.tan_x / cam.width                      # scene units (a metre: 100 cm)
    texel_cm = lambda l: 2.0 ** (l + 3.0) / spec.resolution
    want_footprint = np.floor(np.log2(f * 100.0 * 2.0 ** spec.lod_bias / texel_cm(0))) + 1
    want_cover = np.floor(np.log2(d * 100.0))
    want = np.clip(np.maximum(want_footprint, want_cover), spec.first_level, spec.last_level)
    ok = _off_boundary(np.log2(f * 100.0 * 2.0 ** spec.lod_bias / texel_cm(0))) & _off_boundary(np.log2(d * 100.0))
    assert ok.mean() > 0.99 and len(np.unique(want[ok])) >= 8
    assert np.array_equal(lvl[ok], want[ok])
    assert np.allclose(texel, texel_cm(lvl) / 100.0, rtol=1e-6)
    free = ok & (lvl > spec.first_level) & (lvl < spec.last_level)
    ratio = texel[free] / f[free]
    assert free.sum() > 1000
    lo, hi = 2.0 ** spec.lod_bias, 2.0 ** (spec.lod_bias + 1)
    assert np.all(ratio > lo * (1 - 1e-5)) and np.all(ratio <= hi * (1 + 1e-5))
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    rx = Receiver.make(view, p, mi.Vector3f(0, 0, 1), 1.0, cam)
    assert np.allclose(rx.texel_world.numpy(), texel, rtol=0, atol=0)


def test_eevee_level_covers_the_distance_with_a_tile_to_spare():
    """EEVEE's rule: level l is 2^l m wide, and the receiver's level the smallest with
    2^l >= 2 d T / (T - 1.0001) (T = 32 pages a side): the level's half width covers d."""
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.maps.virtual import VirtualView
    spec = VIRTUAL_PRESETS["eevee"]
    cam, pts = _camera(), _points()
    view = VirtualView(DOWN, spec, cam, pts[:50], (pts.min(0), pts.max(0)))
    lvl, texel = _levels(view, pts)
    d = np.linalg.norm(pts, axis=1)
    x = np.log2(2.0 * d * 32 / (32 - 1.0001))
    ok = _off_boundary(x)
    want = np.clip(np.ceil(x), spec.first_level, spec.last_level)
    assert np.array_equal(lvl[ok], want[ok]) and len(np.unique(want)) >= 8
    assert np.allclose(texel, 2.0 ** lvl / spec.resolution, rtol=1e-6)
    assert np.all(2.0 ** lvl[ok] / 2 >= d[ok])


# ---------------------------------------------------------------- a plane under a directional light

def _plane_setup(res=96):
    import dsm.pipeline as pl
    from dsm.core.types import CameraSpec, LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane", "tilt": 0.0}), (res, res),
                       CameraSpec(position=(0.0, -2.3, 0.35), target=(0.0, 1.5, 0.0)))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=DOWN), "sun")
    return pl, sd, setup


def test_plane_level_histogram_follows_from_each_receivers_distance():
    """On a plane under a straight-down sun, seen at a grazing angle, each receiver's level follows
    from its distance to the camera alone (UE5's footprint rule with the pixel's width at that
    distance): the histogram of levels equals the one derived in float64 here, receivers within
    1e-4 of a level boundary left out (at most 1 %)."""
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.scenes.camera import Camera
    from dsm.truth.virtual import level_histogram
    pl, sd, setup = _plane_setup()
    spec = VIRTUAL_PRESETS["ue5"]
    pts = pl.points_np(setup.p)
    view = pl.make_view(setup.light, spec.resolution, pts, sd.bbox, None, spec, sd.sensor, sd.scale)
    rx = pl.receivers(view, setup, sd.diagonal)
    faces = np.asarray(rx.face.numpy(), int)
    cam = Camera.from_sensor(sd.sensor)
    d = np.linalg.norm(pts - cam.origin, axis=1)
    x_foot = np.log2(2.0 * d * cam.tan_x / cam.width * 100.0 * 2.0 ** spec.lod_bias * spec.resolution / 8.0)
    x_cover = np.log2(d * 100.0)
    want = np.clip(np.maximum(np.floor(x_foot) + 1, np.floor(x_cover)), spec.first_level, spec.last_level)
    ok = _off_boundary(x_foot) & _off_boundary(x_cover)
    assert ok.mean() > 0.99
    levels, counts = np.unique(want[ok], return_counts=True)
    assert len(levels) >= 3            # the grazing view spans several levels
    got = level_histogram(view, faces[ok])
    assert got == {int(a): int(b) for a, b in zip(levels, counts)}
    assert sum(level_histogram(view, faces).values()) == len(pts)
    # every receiver's own page is tagged: its nearest texel is stored
    import drjit as dr
    import mitsuba as mi
    i, j = mi.Int32(dr.floor(rx.u_map)), mi.Int32(dr.floor(rx.v_map))
    _, absent = view.texel_index(rx.face, i, j)
    assert not np.any(absent.numpy())


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["ue5", "eevee"])
def test_levels_and_pages_do_not_depend_on_the_scenes_scale(preset):
    """plane_box at scale 1 and 1024 (a power of two: its float32 geometry scales exactly): the same
    receivers in the same levels, the same pages, and each level 1024 times as wide."""
    import dsm.pipeline as pl
    from dsm.core.types import VIRTUAL_PRESETS, LightSpec
    spec = VIRTUAL_PRESETS[preset]
    out = []
    for scale in (1.0, 1024.0):
        sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box", "scale": scale}), (64, 64), None)
        setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("directional", direction=SLANT), "sun")
        view = pl.make_view(setup.light, spec.resolution, pl.points_np(setup.p), sd.bbox, None, spec, sd.sensor,
                            sd.scale)
        out.append((view, np.asarray(pl.receivers(view, setup, sd.diagonal).face.numpy(), int)))
    (a, fa), (b, fb) = out
    assert np.array_equal(fa, fb) and np.array_equal(a.pages, b.pages) and a.n_pages > 0
    assert np.allclose(b.extents, 1024.0 * a.extents, rtol=1e-12)


# ---------------------------------------------------------------- one level: the single map

def _one_level(pl, sd, setup, all_pages=True, level=None):
    from dataclasses import replace
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.maps.views import OrthographicView
    from dsm.maps.virtual import VirtualView, level_width
    from dsm.scenes.camera import Camera
    base = replace(VIRTUAL_PRESETS["ue5"], resolution=256, page_size=32)
    diag = float(np.linalg.norm(np.asarray(sd.bbox[1]) - np.asarray(sd.bbox[0])))
    # the finest level at least four scene diagonals wide: the camera-centred square covers the scene
    lvl = level if level is not None else int(math.ceil(math.log2(4 * diag * 100.0))) - 3
    spec = replace(base, first_level=lvl, last_level=lvl)
    assert level_width(spec, lvl) >= 4 * diag
    pts = pl.points_np(setup.p)
    vview = VirtualView(setup.light.direction, spec, Camera.from_sensor(sd.sensor), pts, sd.bbox, sd.scale,
                        all_pages=all_pages)
    x0, y0, w = vview.rects[0]
    oview = OrthographicView.square(setup.light.direction, x0, y0, w, sd.bbox, spec.resolution)
    return vview, oview


@pytest.mark.slow
@pytest.mark.parametrize("builtin", ["plane_box", "l_shape"])
def test_one_level_with_every_page_tagged_is_the_single_orthographic_map(builtin):
    """One level covering the scene, every page tagged: the page-list build's z1, slope and z2 equal
    the whole orthographic map's at the same texels, and every scheme and filter sees the same V."""
    import drjit as dr
    import mitsuba as mi
    import dsm.pipeline as pl
    from dsm.core.types import LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": builtin}), (64, 64), None)
    setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("directional", direction=SLANT), "sun")
    vview, oview = _one_level(pl, sd, setup)
    assert vview.n_pages == (256 // 32) ** 2 and vview.n_texels == oview.n_texels
    specs = [pl.scheme_spec({"name": "constant", "bias": b}) for b in (0.0, "1 texel")]
    specs += [pl.scheme_spec(s) for s in ({"name": "slope_scaled"}, {"name": "normal_offset"},
                                           {"name": "receiver_plane"}, {"name": "midpoint"})]
    needs = pl.needs_of(specs)
    mv, mo = pl.build_map(sd.scene, vview, needs), pl.build_map(sd.scene, oview, needs)
    face, cu, cv = vview.texel_coords(dr.arange(mi.UInt32, vview.n_texels))
    at = (np.asarray(cv.numpy()) - 0.5).astype(int) * 256 + (np.asarray(cu.numpy()) - 0.5).astype(int)
    assert not np.any(face.numpy()) and len(np.unique(at)) == vview.n_texels
    for layer in ("z1", "slope", "z2", "shape"):
        assert np.array_equal(getattr(mv, layer).numpy(), getattr(mo, layer).numpy()[at]), layer
    for fmt in ("float32", "unorm16"):
        sv, so = pl.store(mv, fmt), pl.store(mo, fmt)
        rv, ro = pl.receivers(sv.view, setup, sd.diagonal), pl.receivers(so.view, setup, sd.diagonal)
        for spec in specs:
            for filt in ("nearest", "pcf_bilinear", "pcf_wide:3"):
                a, _ = pl.visibility(spec, rv, sv, filt)
                b, _ = pl.visibility(spec, ro, so, filt)
                assert np.array_equal(a.numpy(), b.numpy()), (spec.name, filt, fmt)


def test_tagged_pages_alone_give_the_nearest_lookups_of_the_whole_level():
    """Only the receivers' pages built (a fraction of the level): each receiver's nearest lookup is
    the whole map's, and a texel of a page nobody tagged reads as no caster (the far bound)."""
    import dsm.pipeline as pl
    from dsm.core.types import LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (64, 64), None)
    setup = pl.light_setup(sd, pl.gbuffer(sd), LightSpec("directional", direction=SLANT), "sun")
    vview, oview = _one_level(pl, sd, setup, all_pages=False)
    assert 0 < vview.n_pages < (256 // 32) ** 2
    specs = [pl.scheme_spec({"name": "constant", "bias": b}) for b in (0.0, "1 texel")]
    specs += [pl.scheme_spec({"name": "slope_scaled"}), pl.scheme_spec({"name": "receiver_plane"})]
    needs = pl.needs_of(specs)
    mv, mo = pl.build_map(sd.scene, vview, needs), pl.build_map(sd.scene, oview, needs)
    assert mv.rays["map_texel"] == vview.n_pages * 32 ** 2
    rv, ro = pl.receivers(vview, setup, sd.diagonal), pl.receivers(oview, setup, sd.diagonal)
    for spec in specs:
        a, sa = pl.visibility(spec, rv, mv)
        b, sb = pl.visibility(spec, ro, mo)
        assert np.array_equal(a.numpy(), b.numpy()) and np.array_equal(sa.numpy(), sb.numpy()), spec.name
    from dsm.maps import lookup
    far = lookup.tap_at(rv, mv, rv.u_map * 0 + 0.5, rv.v_map * 0 + 0.5)   # texel (0, 0): a corner page
    untagged = not any((p[1], p[2]) == (0, 0) for p in vview.pages)
    assert untagged and np.all(far.z1.numpy() == np.float32(vview.far)) and np.all(far.shape.numpy() == 0xFFFFFFFF)


# ---------------------------------------------------------------- a run

@pytest.mark.slow
def test_a_run_reports_pages_memory_rays_and_levels(run_dict):
    """metrics.csv's vsm_* columns: pages (tagged = built), physical texels = pages x page_size^2,
    rays = those texels (one per texel without a second layer), the level histogram summing to the
    receivers; virtual.md, report.html's section and each case's level image."""
    cfg = base_config(scene=[{"builtin": "long_ground"}], camera={"resolution": [48, 48]},
                      map={"virtual": {"preset": ["ue5", "eevee"], "resolution": 4096, "page_size": 64}},
                      scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}])
    res = run_dict(cfg, "vsm", report=True)
    assert len(res.rows) == 4
    for r in res.rows:
        page = 64
        assert r["vsm_pages_tagged"] == r["vsm_pages_built"] > 0
        assert r["vsm_memory_texels"] == r["vsm_pages_tagged"] * page ** 2 == r["vsm_rays"]
        hist = dict(w.split(":") for w in r["vsm_level_histogram"].split())
        assert sum(map(int, hist.values())) == r["n_receivers"] > 0
        pages = dict(w.split(":") for w in r["vsm_level_pages"].split())
        assert sum(map(int, pages.values())) == r["vsm_pages_tagged"] and set(hist) <= set(pages)
        assert r["cascade_layout"].startswith("vsm ")
    from dsm.report import figures
    folder = res.out / "images" / figures.image_folder(res.rows[0])
    assert (folder / f"{res.rows[0]['case']}_level.png").is_file()
    text = (res.out / "virtual.md").read_text()
    assert "# Virtual shadow maps" in text and res.rows[0]["vsm_level_histogram"] in text
    assert "Virtual shadow maps</h2>" in (res.out / "report.html").read_text()


@pytest.mark.parametrize("table,key", [
    ({"preset": "unreal"}, "map.virtual.preset"),
    ({"pages": 2}, "map.virtual.pages"),
    ({"resolution": 1000}, "map.virtual.resolution"),
    ({"first_level": 9, "last_level": 3}, "map.virtual.last_level"),
    ({"rule": "nearest"}, "map.virtual.rule"),
    ({"border": 0.7}, "map.virtual.border"),
    ({"levels": 3, "last_level": 9}, "map.virtual.levels"),
    ({"levels": 0}, "map.virtual.levels"),
])
def test_bad_virtual_keys_are_config_errors_naming_the_key(table, key):
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    cfg = base_config(light=[{"type": "directional", "direction": [0, 0, -1]}], map={"virtual": table})
    with pytest.raises(ConfigError) as e:
        config.parse(cfg, "t.toml")
    assert e.value.key == key and "t.toml" in str(e.value)


def test_levels_counts_from_the_first_level_and_presets_keep_the_other_keys():
    from dsm.config import read as config
    from dsm.core.types import VIRTUAL_PRESETS
    cfg = config.parse(base_config(map={"virtual": {"preset": ["ue5", "eevee"], "first_level": 2, "levels": 5}}),
                       "t.toml")
    ue5, eevee = cfg.map.virtual
    assert (ue5.first_level, ue5.last_level, ue5.count) == (2, 6, 5) and (eevee.first_level, eevee.last_level) == (2, 6)
    assert ue5.page_size == VIRTUAL_PRESETS["ue5"].page_size and eevee.rule == "distance"
    assert ue5.label == "vsm ue5 first_level=2 last_level=6"


def test_virtual_without_a_directional_light_is_a_config_error():
    from dsm.config import read as config
    from dsm.config import plan
    from dsm.core.types import ConfigError
    spot = {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0]}
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(light=[spot], map={"virtual": {"preset": "ue5"}}), "t.toml")
    assert e.value.key == "map.virtual" and "directional" in str(e.value)
    cfg = config.parse(base_config(scene=[{"builtin": "room"}], map={"virtual": {}}), "t.toml")
    with pytest.raises(ConfigError) as e:
        plan.make(cfg)                      # the room's own light is a point light
    assert e.value.key == "map.virtual"
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(map={"virtual": {}, "kind": ["depth", "vsm"]}), "t.toml")
    assert e.value.key in ("map.virtual", "map.kind")


def test_report_html_has_no_virtual_section_without_a_virtual_map():
    """A run without a virtual map holds its six virtual columns as NaN in memory (empty in the file):
    no section for them; a virtual row gets one, its table in a box that scrolls sideways."""
    from dsm.report.sections import virtual as section
    nan = float("nan")
    assert section.html_section([{"vsm_pages_tagged": nan}, {"vsm_pages_tagged": ""}, {}]) == ""
    got = section.html_section([{"vsm_pages_tagged": 3, "case": "c"}])
    assert "<section id=virtual>" in got and '<div class="wide"><table>' in got
