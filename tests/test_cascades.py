"""Cascaded shadow maps (dsm.maps.cascades): splits, cascade choice, the single-map identity, texel
footprints per cascade, stabilization, clipped near/far, the camera pose and config errors.
Expected values come from closed forms and float64 numpy computed here."""

import numpy as np
import pytest

from conftest import base_config

LIGHT = {"type": "directional", "direction": [0.2, -0.5, -0.6]}


def _setup(builtin="long_ground", res=64, camera=None, light=LIGHT, **params):
    import dsm.pipeline as pl
    from dsm.core.types import CameraSpec, LightSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": builtin, **params}), (res, res),
                       CameraSpec(**camera) if camera else None)
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=tuple(light["direction"])), "sun")
    return pl, sd, gb, setup


def _view(pl, sd, setup, R=128, **spec):
    from dsm.core.types import CascadeSpec
    return pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox, None, CascadeSpec(**spec), sd.sensor, sd.scale)


def _np3(v):
    return np.stack([np.asarray(c.numpy(), np.float64) for c in (v.x, v.y, v.z)], axis=1)


# ---------------------------------------------------------------- splits

@pytest.mark.parametrize("kind,lam", [("uniform", 0.5), ("log", 0.5), ("practical", 0.0), ("practical", 0.5),
                                      ("practical", 0.9)])
def test_split_distances_equal_the_closed_forms(kind, lam):
    from dsm.maps.cascades import split_distances
    n, f, N = 0.1, 150.0, 4
    got = split_distances(kind, N, n, f, lam)
    uni = [n + (f - n) * i / N for i in range(N + 1)]
    log = [n * (f / n) ** (i / N) for i in range(N + 1)]
    want = {"uniform": uni, "log": log}.get(kind) or [lam * a + (1 - lam) * b for a, b in zip(log, uni)]
    assert np.allclose(got, want, rtol=1e-14, atol=0)
    assert got[0] == n and got[-1] == f


def test_engine_layouts_bounds():
    """Bevy: first far bound 10, maximum 150, spaced geometrically (10 * 15^(i/3)); Godot: 0.1, 0.2,
    0.5, 1 of its max distance 100."""
    from dsm.maps.cascade_layouts import LAYOUTS
    from dsm.maps.cascades import layout_splits
    bevy = layout_splits(LAYOUTS["bevy"][0], 0.1, 150.0)
    assert np.allclose(bevy, [0.1, 10.0, 10.0 * 15 ** (1 / 3), 10.0 * 15 ** (2 / 3), 150.0], rtol=1e-12)
    godot = LAYOUTS["godot"][0]
    assert np.allclose(layout_splits(godot, 0.05, godot.max_distance), [0.05, 10, 20, 50, 100])


# ---------------------------------------------------------------- cascade choice

def test_each_receiver_is_looked_up_in_the_cascade_whose_range_holds_its_depth():
    from dsm.maps.lookup import nearest_tap
    pl, sd, gb, setup = _setup()
    view = _view(pl, sd, setup, count=4, split="practical", lam=0.5, fit="cascade")
    rx = pl.receivers(view, setup, sd.diagonal)
    p = pl.points_np(setup.p)
    cam_o = np.array(sd.sensor.world_transform().matrix.numpy(), float).reshape(4, 4)[:3, 3]
    fwd = np.array(sd.sensor.world_transform().matrix.numpy(), float).reshape(4, 4)[:3, 2]
    depth = (p - cam_o) @ (fwd / np.linalg.norm(fwd))
    n, f = view.splits[0], view.splits[-1]
    splits = 0.5 * (n * (f / n) ** (np.arange(5) / 4)) + 0.5 * (n + (f - n) * np.arange(5) / 4)
    want = np.searchsorted(splits[1:-1], depth, side="right")
    got = rx.face.numpy().astype(int)
    near_split = np.min(np.abs(depth[:, None] - splits[None, 1:-1]), axis=1) < 1e-5 * depth
    assert np.array_equal(got[~near_split], want[~near_split])
    assert len(np.unique(got)) >= 3                       # several cascades hold receivers
    tap = nearest_tap(rx, pl.store(pl.build_map(sd.scene, view), "float32"))
    assert np.array_equal(tap.idx.numpy() // (view.resolution ** 2), got)   # the texel read is in that cascade
    assert view.inside(setup.p).numpy().all()             # every receiver inside its cascade's map


# ---------------------------------------------------------------- one cascade = today's single map

@pytest.mark.parametrize("builtin", ["plane_box", "long_ground"])
def test_one_cascade_fit_receivers_equals_the_single_map(builtin):
    """Bit-identical z1 and the same visibility per receiver, for every scheme, filter and format."""
    from dsm.maps.views import OrthographicView
    pl, sd, gb, setup = _setup(builtin, res=96)
    pts = pl.points_np(setup.p)
    ortho = pl.make_view(setup.light, 128, pts, sd.bbox)
    assert isinstance(ortho, OrthographicView)
    casc = _view(pl, sd, setup, count=1, fit="receivers", depth_bounds="scene")
    specs = [pl.scheme_spec({"name": "constant", "bias": b}) for b in (0.0, "1 texel", 0.02)]
    specs += [pl.scheme_spec({"name": "slope_scaled"}), pl.scheme_spec({"name": "normal_offset"}),
              pl.scheme_spec({"name": "receiver_plane"})]
    needs = pl.needs_of(specs)
    ma, mb = pl.build_map(sd.scene, ortho, needs), pl.build_map(sd.scene, casc, needs)
    assert np.array_equal(ma.z1.numpy(), mb.z1.numpy()) and np.array_equal(ma.slope.numpy(), mb.slope.numpy())
    for fmt in ("float32", "unorm16"):
        sa, sb = pl.store(ma, fmt), pl.store(mb, fmt)
        ra, rb = pl.receivers(sa.view, setup, sd.diagonal), pl.receivers(sb.view, setup, sd.diagonal)
        for spec in specs:
            for filt in ("nearest", "pcf_bilinear"):
                va, _ = pl.visibility(spec, ra, sa, filt)
                vb, _ = pl.visibility(spec, rb, sb, filt)
                assert np.array_equal(va.numpy(), vb.numpy()), (spec.name, filt, fmt)


@pytest.mark.slow
def test_one_cascade_in_the_runner_counts_as_the_single_map(run_dict):
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [64, 64]},
                      scheme=[{"name": "constant", "bias": [0.0, "1 texel"]}, {"name": "normal_offset"}])
    a = run_dict(cfg, "single")
    b = run_dict({**cfg, "map": {"resolution": 128, "cascades": 1, "fit": "receivers", "depth_bounds": "scene"}},
                 "cascaded")
    keys = ("n_receivers", "n_acne", "n_peterpan", "n_gt_lit", "n_acne_resolution")
    assert [[r[k] for k in keys] for r in a.rows] == [[r[k] for k in keys] for r in b.rows]
    assert all(r["n_receivers"] > 0 for r in a.rows) and any(r["n_acne"] > 0 for r in a.rows)
    from dsm.report import figures
    folder = b.out / "images" / figures.image_folder(b.rows[0])
    assert (b.out / "cascades.csv").is_file() and (folder / f"{b.rows[0]['case']}_cascade.png").is_file()


# ---------------------------------------------------------------- bias per cascade

def test_one_texel_in_cascade_k_is_that_cascades_measured_footprint():
    import drjit as dr
    import mitsuba as mi
    from dsm.maps.lookup import resolve
    pl, sd, gb, setup = _setup()
    view = _view(pl, sd, setup, count=4, split="log", fit="cascade")
    rx = pl.receivers(view, setup, sd.diagonal)
    bias = resolve(pl.scheme_spec({"name": "constant", "bias": "1 texel"}).params, rx).bias.numpy()
    face = rx.face.numpy().astype(int)
    sizes = []
    for k in range(4):
        # the measured footprint: the distance between the rays of the first and the last texel
        # centre of a row (and of a column) of cascade k, over R - 1 texels (float32 rays, float64 here)
        R = view.resolution
        f = dr.full(mi.UInt32, k, 2)
        o, _ = view.ray_at(mi.Float([0.5, R - 0.5]), mi.Float([0.5, 0.5]), f)
        oy, _ = view.ray_at(mi.Float([0.5, 0.5]), mi.Float([0.5, R - 0.5]), f)
        o, oy = _np3(o), _np3(oy)
        step = np.linalg.norm(o[1] - o[0]) / (R - 1)
        assert abs(np.linalg.norm(oy[1] - oy[0]) / (R - 1) - step) < 1e-4 * step      # square texels
        sizes.append(step)
        if (face == k).any():
            assert np.allclose(bias[face == k], step, rtol=1e-4)
    assert len(set(np.round(sizes, 9))) == 4 and sizes == sorted(sizes)   # each cascade its own, growing


# ---------------------------------------------------------------- stabilization

def _texel_rays(view, k):
    R = view.resolution
    r = view.texel_rays(k * R * R, R * R)
    return (np.stack([np.asarray(c.numpy()) for c in (r.o.x, r.o.y, r.o.z)], 1).reshape(R, R, 3),
            np.stack([np.asarray(c.numpy()) for c in (r.d.x, r.d.y, r.d.z)], 1).reshape(R, R, 3))


@pytest.mark.parametrize("stabilize", [True, False])
def test_stabilized_cascades_have_bit_identical_texel_rays_under_camera_translation(stabilize):
    """Two cameras 1.37 units apart sideways: where cascade k of both frames covers the same world
    place, a stabilized texel ray is the same float32 ray (origin and direction), because its
    extent (a quantized sphere radius) is the same and its origin is the fixed anchor plus whole
    texels; without stabilization the fit follows the camera and the rays differ."""
    import dsm.pipeline as pl
    views = []
    for dx in (0.0, 1.37):
        pl_, sd, gb, setup = _setup(camera={"position": [-90.0, -2.0 + dx, 3.0], "target": [-50.0, -2.0 + dx, 0.0]})
        views.append(_view(pl, sd, setup, count=4, split="practical", lam=0.7, fit="cascade", stabilize=stabilize,
                           max_distance=120.0))
    a, b = views
    R = a.resolution
    overlapping, sames, moved = 0, [], []
    for k in range(4):
        if stabilize:
            assert a.extents[k] == b.extents[k]
        oa, da = _texel_rays(a, k)
        ob, db = _texel_rays(b, k)
        if stabilize:
            # texel (i, j) of a is texel (i + da_u, j + da_v) of b: whole texels between the two corners
            nu = int(round(float(a.NU.numpy()[k]) - float(b.NU.numpy()[k])))
            nv = int(round(float(a.NV.numpy()[k]) - float(b.NV.numpy()[k])))
        else:
            t = a.extents[k] / R
            nu = int(round((a.rects[k][0] - b.rects[k][0]) / t))
            nv = int(round((a.rects[k][1] - b.rects[k][1]) / t))
        moved.append((nu, nv) != (0, 0))
        ia = slice(max(0, -nu), min(R, R - nu)), slice(max(0, -nv), min(R, R - nv))
        ib = slice(max(0, nu), min(R, R + nu)), slice(max(0, nv), min(R, R + nv))
        pa, pb = oa[ia[1], ia[0]], ob[ib[1], ib[0]]            # rows are v (j), columns u (i)
        overlapping += pa.shape[0] * pa.shape[1]
        sames.append(np.array_equal(pa, pb) and np.array_equal(da, db))
    # unstabilized, a cascade clipped to the scene's far end may keep its square, the near ones move
    assert all(sames) if stabilize else not all(sames)
    assert overlapping > R * R and any(moved)             # they overlap, and the squares moved                                  # the cascades overlap in world space


# ---------------------------------------------------------------- near and far

def test_light_frustum_clipped_to_the_scene_bounds():
    """intersect_hexahedra against a dense sampling of one box kept where it lies in the other."""
    from dsm.maps.cascades import box_corners, intersect_hexahedra
    rng = np.random.default_rng(3)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    a = box_corners([-1, -2, -0.5], [3, 1, 0.5]) @ rot.T       # an oriented box
    b = box_corners([0.2, -0.7, -5.0], [1.1, 0.4, 5.0])        # a light prism (axis-aligned, long in z)
    pts = intersect_hexahedra(a, b)
    g = np.stack(np.meshgrid(*(np.linspace(0, 1, 61),) * 3, indexing="ij"), -1).reshape(-1, 3)
    lo, hi = np.array([-1, -2, -0.5]), np.array([3, 1, 0.5])
    samples = (lo + g * (hi - lo)) @ rot.T
    keep = samples[np.all((samples >= [0.2, -0.7, -5.0]) & (samples <= [1.1, 0.4, 5.0]), 1)]
    assert len(keep) > 100
    step = np.linalg.norm((hi - lo) / 60)
    assert pts[:, 2].min() <= keep[:, 2].min() + 1e-12 and pts[:, 2].max() >= keep[:, 2].max() - 1e-12
    assert keep[:, 2].min() - pts[:, 2].min() < step and pts[:, 2].max() - keep[:, 2].max() < step


def test_clipped_near_far_is_within_the_naive_bounds_and_tighter_on_long_ground():
    pl, sd, gb, setup = _setup()
    clipped = _view(pl, sd, setup, count=4, split="log", fit="cascade")
    naive = _view(pl, sd, setup, count=4, split="log", fit="cascade", depth_bounds="scene")
    ez = naive.axes_np[2]
    lo, hi = sd.bbox
    zs = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)]) @ ez
    naive_range = (zs.max() - zs.min()) + 2 * 0.01 * max(zs.max() - zs.min(), sd.diagonal)
    assert np.allclose(naive.face_far - naive.face_near, naive_range)
    assert np.all(clipped.face_far - clipped.face_near < naive_range)
    assert (clipped.face_far - clipped.face_near)[0] < 0.5 * naive_range    # the first cascade sees a sliver


# ---------------------------------------------------------------- camera pose and config

def test_camera_pose_overrides_and_far_plane_is_the_farthest_corner():
    import mitsuba as mi
    pl, sd, gb, setup = _setup("plane_box", camera={"position": [4.0, -3.0, 2.0], "target": [0.0, 0.0, 0.5],
                                                    "fov": 50.0}, scale=2.0)
    m = np.array(sd.sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    assert np.allclose(m[:3, 3], [8.0, -6.0, 4.0], atol=1e-5)               # the config's position, scaled
    fwd = np.array([-8.0, 6.0, -3.0])
    assert np.allclose(m[:3, 2], fwd / np.linalg.norm(fwd), atol=1e-6)
    params = mi.traverse(sd.sensor)
    assert abs(float(params["x_fov"][0]) - 50.0) < 1e-4
    lo, hi = sd.bbox
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    far = ((corners - [8.0, -6.0, 4.0]) @ (fwd / np.linalg.norm(fwd))).max() * 1.01
    assert abs(float(np.ravel(params["far_clip"])[0]) - far) < 1e-4 * far


def test_cascades_without_a_directional_light_is_a_config_error():
    from dsm.config import read as config
    from dsm.config import plan
    from dsm.core.types import ConfigError
    spot = {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0]}
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(light=[spot], map={"cascades": 4}), "t.toml")
    assert e.value.key == "map.cascades" and "directional" in str(e.value)
    cfg = config.parse(base_config(scene=[{"builtin": "room"}], map={"cascades": 4}), "t.toml")
    with pytest.raises(ConfigError) as e:
        plan.make(cfg)                      # the room's own light is a point light
    assert e.value.key == "map.cascades"
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(map={"cascades": 9}), "t.toml")
    assert e.value.key == "map.cascades"
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(map={"cascades": 2, "fit": "tight"}), "t.toml")
    assert e.value.key == "map.fit" and "frustum" in e.value.choices
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(map={"cascades": "bevy", "split": "log"}), "t.toml")
    assert e.value.key == "map.split"


@pytest.mark.parametrize("camera,key", [
    ({"target": [-99.0, 0.0, 3.0]}, "camera.target"),          # long_ground's own position
    ({"position": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0]}, "camera.up"),   # down the default up
    ({"up": [39.0, 0.0, -3.0]}, "camera.up"),                  # along long_ground's own view
    ({"near": 1e-20}, "camera.near"),                          # below 1e-12 of the distance: no ray would be cast
])
def test_a_camera_pose_that_cannot_look_is_a_config_error_not_a_traceback(tmp_path, capsys, camera, key):
    """The pose is completed by the scene's own, so only loading the scene sees it: still exit 2
    before any work, one line naming the file and the key."""
    from dsm.cli import main
    cfg = tmp_path / "c.toml"
    lines = "".join(f"{k} = {v}\n" for k, v in camera.items())
    cfg.write_text('[[scene]]\nbuiltin = "long_ground"\n[[scheme]]\nname = "none"\n[map]\nresolution = 16\n'
                   f'[camera]\nresolution = [8, 8]\n{lines}')
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{cfg}: {key}:" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_a_tiny_near_clip_still_sees_the_scene(run_dict):
    """near = 1e-9 (about 1e-10 of plane_box's camera distance, above the refused 1e-12) gives the receivers of the
    default near clip: the clip is in front of every surface either way."""
    a = run_dict(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]}), "a").rows[0]
    b = run_dict(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48], "near": 1e-9}),
                 "b").rows[0]
    assert a["n_receivers"] > 0 and a["n_receivers"] == b["n_receivers"]


def test_blend_mixes_the_next_cascade_linearly_over_the_band():
    """Over the last 30 % of the first split V = (1 - w) V_0 + w V_1, w = (d - band start) / band
    (float64 here); elsewhere V is the receiver's own cascade's."""
    import dataclasses
    import drjit as dr
    import mitsuba as mi
    from dsm.maps import lookup
    from dsm import schemes
    pl, sd, gb, setup = _setup()
    view = _view(pl, sd, setup, count=2, split="practical", lam=0.9, fit="cascade", blend=0.3)
    smap = pl.store(pl.build_map(sd.scene, view), "float32")
    rx = pl.receivers(view, setup, sd.diagonal)
    spec = pl.scheme_spec({"name": "constant", "bias": "0.3 texel"})
    v = pl.visibility(spec, rx, smap)[0].numpy()
    v0 = lookup.visibility(schemes.get("constant"), spec.params, rx, smap)[0].numpy()
    one = dr.full(mi.UInt32, 1, dr.width(rx.face))
    u1, v1_ = view.project_on(rx.p_world, one)
    rx1 = dataclasses.replace(rx, face=one, u_map=u1, v_map=v1_, texel_world=view.texel_world(rx.p_world) * 0
                              + float(view.extents[1] / view.resolution))
    v1 = lookup.visibility(schemes.get("constant"), spec.params, rx1, smap)[0].numpy()
    m = np.array(sd.sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    d = (pl.points_np(setup.p) - m[:3, 3]) @ m[:3, 2]
    s0, s1 = view.splits[0], view.splits[1]
    start = s1 - 0.3 * (s1 - s0)
    face = rx.face.numpy()
    w = np.clip((d - start) / (s1 - start), 0, 1)
    band = (face == 0) & (d > start)
    assert band.sum() > 50 and ((v[band] > 0) & (v[band] < 1)).any()
    assert np.allclose(v[band], (1 - w[band]) * v0[band] + w[band] * v1[band], atol=1e-4)
    assert np.array_equal(v[~band], v0[~band])


def test_camera_pose_replaces_an_xml_sensors_and_keeps_its_film(tmp_path):
    import mitsuba as mi
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="45"/>'
                   '<transform name="to_world"><lookat origin="0, -4, 3" target="0, 0, 0" up="0, 0, 1"/></transform>'
                   '<film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="30"/></film>'
                   '</sensor><shape type="rectangle"/><emitter type="directional"><vector name="direction" '
                   'value="0.1, 0.2, -1"/></emitter></scene>')
    cfg = config.parse({"scene": [{"file": str(xml)}], "camera": {"position": [3.0, 1.0, 2.0], "fov": 30.0},
                        "scheme": [{"name": "none"}]}, "<t>")
    sd = scenes.load(cfg.scenes[0], cfg.camera_resolution, cfg.camera)
    m = np.array(sd.sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    assert np.allclose(m[:3, 3], [3.0, 1.0, 2.0], atol=1e-5)
    assert tuple(sd.sensor.film().size()) == (40, 30)
    assert abs(float(mi.traverse(sd.sensor)["x_fov"][0]) - 30.0) < 1e-4
    # without a target it looks at the XML's: the point of its view axis nearest the scene's centre,
    # here the origin (the rectangle's centre lies on the axis from (0, -4, 3) to (0, 0, 0))
    assert np.allclose(m[:3, 2], -np.array([3.0, 1.0, 2.0]) / np.sqrt(14.0), atol=1e-5)
