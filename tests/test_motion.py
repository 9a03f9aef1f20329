"""Motion (dsm.experiment.motion): flicker of fixed points over frames. Static frames flicker 0; stabilized
cascades under a sideways camera flicker 0 within a cascade; a fixed point's exact visibility
does not depend on the camera; the flicker arithmetic against counts made by hand."""
import csv
import numpy as np

import pytest

from conftest import cli_run as _cli, one_line as _one_line, base_config, toml_text

SCHEMES = [{"name": "none"}, {"name": "constant", "bias": ["1 texel", 0.02]}, {"name": "normal_offset"},
           {"name": "receiver_plane"}, {"preset": "bevy"}]


def _frames(res):
    with open(res.out / "frames.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_flicker_counts_by_hand():
    """Three frames, five points: the pairs' eligible sets, flips, cascade changes and |dV| here."""
    from dsm.experiment.motion import flicker
    v = np.array([[1.0, 0.0, 1.0, 0.25, 1.0], [0.0, 0.0, 1.0, 0.75, 1.0], [1.0, 1.0, 1.0, 0.75, 0.0]])
    vstar = np.array([[1, 0, 1, 1, 1], [1, 0, 1, 1, 1], [1, 1, 1, 1, 1]], bool)
    elig = np.array([[1, 1, 1, 1, 0], [1, 1, 1, 1, 1], [1, 1, 0, 1, 1]], bool)
    face = np.array([[0, 0, 0, 1, 1], [0, 0, 0, 2, 1], [0, 0, 0, 2, 1]])
    pairs, ever = flicker(v, vstar, elig, face)
    # pair (0, 1): points 0..3 eligible; point 0 flips (within), point 3 flips (0.25 -> 0.75, cascade 1 -> 2)
    assert pairs[0]["n_pairs_eligible"] == 4 and pairs[0]["n_flicker"] == 2
    assert pairs[0]["flicker_within_rate"] == 1 / 3 and pairs[0]["flicker_change_rate"] == 1.0
    assert pairs[0]["flicker_magnitude"] == pytest.approx((1 + 0 + 0 + 0.5) / 4)
    # pair (1, 2): point 1's V* changes (left out), point 2 not eligible in frame 2; 0, 3, 4 eligible; 0 and 4 flip
    assert pairs[1]["n_pairs_eligible"] == 3 and pairs[1]["n_flicker"] == 2 and pairs[1]["flicker_rate"] == 2 / 3
    assert np.isnan(pairs[1]["flicker_change_rate"])          # no cascade change: undefined, not 0
    # ever: points 0, 3, 4 flip at least once, of the 5 eligible in some pair... point 1 and 2 were eligible in pair 0
    assert ever == 3 / 5


@pytest.mark.slow
def test_static_camera_and_light_flicker_zero_for_every_scheme(run_dict):
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [64, 64]}, scheme=SCHEMES,
                      map={"resolution": 128, "filter": ["nearest", "pcf_jitter4x4"]},
                      motion=[{"frames": 3, "points": 1500}])
    res = run_dict(cfg, report=True)
    assert len(res.rows) == 2 * 6
    for r in res.rows:
        assert r["flicker_rate"] == 0 and r["flicker_ever"] == 0 and r["flicker_magnitude"] == 0, r["case"]
        assert r["maps_built"] == 1                      # neither the light nor its projection moved: one map
    frames = _frames(res)
    assert len(frames) == 12 * 3 and all(int(f["n_pairs_eligible"]) > 100 for f in frames if f["frame"] != "0")
    assert len(list((res.out / "images").glob("*/0001_frames.gif"))) == 1     # in its scene-light folder


@pytest.mark.slow
def test_report_images_none_writes_no_frames_gif_and_the_same_numbers(run_dict):
    """[report] images = "none" means no image at all, the motion GIF included; "errors" keeps it
    (it is the frames' error images). The numbers do not depend on it."""
    runs = {}
    for images in ("none", "errors"):
        cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                          map={"resolution": 32}, scheme=[{"name": "constant"}], report={"images": images},
                          motion=[{"frames": 2, "camera": "dolly", "offset": [0.0, 0.3, 0.0], "points": 300}])
        runs[images] = run_dict(cfg, images, report=True)
    assert [p.name for p in (runs["none"].out / "images").rglob("*") if p.is_file()] == []
    assert len(list((runs["errors"].out / "images").glob("*/0001_frames.gif"))) == 1
    keep = ("case", "n_receivers", "n_acne", "n_peterpan", "flicker_rate", "flicker_ever")
    assert [{k: r[k] for k in keep} for r in runs["none"].rows] == [{k: r[k] for k in keep} for r in runs["errors"].rows]


@pytest.mark.slow
@pytest.mark.parametrize("stabilize", [True, False])
def test_stabilized_cascades_do_not_flicker_within_a_cascade(run_dict, stabilize):
    """Why stabilized flicker within a cascade is exactly 0: a fixed point's depth is measured from
    the fixed anchor and its map position is its float32 position from the anchor in texels (the
    same in every frame) less the whole offset of the square's corner, an exact subtraction; so it
    reads the same world texel, whose ray is the same float32 ray (anchor + whole texel index x
    texel size, the texel size the same quantized sphere's), which hits the same surface at the
    same float32 depth; a texel bias is the same texel size, so the comparison is the same. Without
    stabilization each frame's square follows the camera by fractions of a texel: the texels sample
    other places, and edges move."""
    cfg = base_config(scene=[{"builtin": "long_ground"}], camera={"resolution": [96, 96]},
                      scheme=[{"name": "constant", "bias": "1 texel"}],
                      map={"resolution": 256, "cascades": 4, "split": "practical", "lambda": 0.5, "fit": "cascade",
                           "max_distance": 120.0, "stabilize": stabilize},
                      motion=[{"frames": 5, "camera": "dolly", "offset": [0.0, 3.0, 0.0], "points": 4000}])
    res = run_dict(cfg)
    frames = [f for f in _frames(res) if f["frame"] != "0"]
    within = sum(int(f["n_eligible_within"]) for f in frames)
    assert within > 1000
    rates = [float(f["flicker_within_rate"]) for f in frames]
    if stabilize:
        assert all(x == 0 for x in rates)
    else:
        assert sum(rates) > 0


def test_fixed_points_exact_visibility_does_not_depend_on_the_camera():
    """An orbit of 60 degrees: each frame's V* of every fixed point is the same, and agrees with
    Mitsuba's own spawned shadow rays (an independent offset) on all but a sliver."""
    import dsm.pipeline as pl
    from dsm.experiment import motion
    from dsm.truth import reference
    from dsm.scenes.camera import Camera
    from dsm.core.types import LightSpec, MotionSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (48, 48))
    light = LightSpec("directional", direction=(-0.4, -0.3, -1.0))
    fp = motion.sample_points(sd.scene, 2000, 7, sd.diagonal)
    base = Camera.from_sensor(sd.sensor)
    mag = pl.scene_magnitude(sd.bbox)
    vs, eligs = [], []
    for o, t, up in motion.camera_path(MotionSpec(frames=4, camera="orbit", angle=60.0), base, sd.bbox):
        sensor = motion.sensor_at(base, o, t, up)
        gb = pl.gbuffer(sd, sensor=sensor)
        setup = pl.light_setup(sd, gb, light, "sun")
        view = pl.make_view(light, 128, pl.points_np(setup.p), sd.bbox)
        elig, vstar, _ = motion.points_frame(sd.scene, fp, Camera.from_sensor(sensor), light, view, mag)
        vs.append(vstar)
        eligs.append(elig)
    assert all(np.array_equal(vs[0], v) for v in vs[1:])
    assert not all(np.array_equal(eligs[0], e) for e in eligs[1:])      # the camera did move
    mts = reference.visibility(sd.scene, fp.si, light, mag, mitsuba_spawn=True)[0].numpy().astype(bool)
    assert (mts != vs[0]).mean() < 0.01 and 0.1 < vs[0].mean() < 0.99


def test_motion_config_errors_name_the_key():
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    for motion, key in (({"frames": 1}, "motion[0].frames"), ({"camera": "dolly"}, "motion[0].offset"),
                        ({"camera": "zoom"}, "motion[0].camera"), ({"light": "turn"}, "motion[0].light_angle"),
                        ({"camera": "keyframes", "keys": [{"position": [0, 0, 1]}]}, "motion[0].keys"),
                        ({"speed": 2}, "motion[0].speed"),
                        ({"camera": "keyframes", "keys": [{"position": [0, 0, 1], "target": [0, 0, 1]},
                                                          {"position": [0, 1, 1], "target": [0, 0, 0]}]},
                         "motion[0].keys[0].target"),
                        ({"light": "keyframes", "light_keys": [{"position": [0, 0, 4], "target": [0, 0, 4]},
                                                               {"position": [1, 0, 4], "target": [0, 0, 0]}]},
                         "motion[0].light_keys[0].target")):
        with pytest.raises(ConfigError) as e:
            config.parse(base_config(motion=[motion]), "t.toml")
        assert e.value.key == key, (motion, e.value)
    spot = {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0]}
    with pytest.raises(ConfigError) as e:     # the second path turns the sun, and there is none
        config.parse(base_config(light=[spot], motion=[{"camera": "orbit", "angle": 30},
                                                       {"light": "turn", "light_angle": 2}]), "t.toml")
    assert e.value.key == "motion[1].light" and list(e.value.choices) == ["directional"]
    cfg = config.parse(base_config(motion=[{"camera": "orbit", "angle": 30}, {"light": "turn", "light_angle": 2}]),
                       "t.toml")
    assert [m.label for m in cfg.motion] == ["camera orbit", "sun turn 2deg"]


def _segment_hits_box(p, q, lo, hi):
    """Whether the segments p -> q (n x 3, float64) meet the box [lo, hi] (slab test)."""
    d = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - p) / d, (hi - p) / d
    tmin = np.where(d == 0, np.where((p >= lo) & (p <= hi), -np.inf, np.inf), np.minimum(t1, t2))
    tmax = np.where(d == 0, np.where((p >= lo) & (p <= hi), np.inf, -np.inf), np.maximum(t1, t2))
    enter, leave = np.max(tmin, axis=1), np.min(tmax, axis=1)
    return (enter <= leave) & (leave >= 0) & (enter <= 1)


@pytest.mark.parametrize("scale,translate", [(1.0, [0.0, 0.0, 0.0]), (2.0, [300.0, -50.0, 7.0])])
def test_moving_point_light_exact_visibility_matches_the_segment_test(scale, translate):
    """A point light moving along light_offset over plane_box: each frame's light is the start
    moved by the offset times the frame's fraction (scaled with the scene), and the kit's V* of
    every fixed point on the ground (outside the box's footprint) is the analytic answer: lit
    exactly when the segment to the light misses the box [-0.5, 0.5]^2 x [0, 1] (numpy float64,
    scaled and moved as the scene; points within 1e-3 of the box's silhouette are left out)."""
    import dsm.pipeline as pl
    from dsm.experiment import motion
    from dsm.scenes.camera import Camera
    from dsm.core.types import LightSpec, MotionSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box", "scale": scale, "translate": translate}), (48, 48))
    light = sd.lights_for([LightSpec("point", position=(-1.5, 0.0, 2.5))])[0]
    spec = MotionSpec(frames=5, light="move", light_offset=(3.0, 0.8, 0.0))
    frames = motion.light_path(spec, light, sd.scale, sd.offset)
    t = np.asarray(translate)
    for i, lf in enumerate(frames):
        want = (np.array([-1.5, 0.0, 2.5]) + np.array([3.0, 0.8, 0.0]) * i / 4) * scale + t
        assert np.allclose(lf.position, want, rtol=0, atol=1e-9 * scale)
    fp = motion.sample_points(sd.scene, 3000, 11, sd.diagonal)
    p = pl.points_np(fp.p).astype(np.float64)
    eps = 1e-3 * scale
    lo, hi = np.array([-0.5, -0.5, 0.0]) * scale + t, np.array([0.5, 0.5, 1.0]) * scale + t
    ground = (np.abs(p[:, 2] - t[2]) < 1e-5 * scale) & \
        ((np.abs(p[:, 0] - t[0]) > 0.5 * scale + 2 * eps) | (np.abs(p[:, 1] - t[1]) > 0.5 * scale + 2 * eps))
    base = Camera.from_sensor(sd.sensor)
    mag = pl.scene_magnitude(sd.bbox)
    vstars, checked = [], 0
    for lf in frames:
        view = pl.make_view(lf, 64, np.zeros((1, 3)), sd.bbox, "cube")
        _, vstar, _ = motion.points_frame(sd.scene, fp, base, lf, view, mag)
        q = np.broadcast_to(np.asarray(lf.position, np.float64), p.shape)
        blocked = _segment_hits_box(p, q, lo + eps, hi - eps)
        clear = ~_segment_hits_box(p, q, lo - eps, hi + eps)
        sure = ground & (blocked | clear)
        assert np.array_equal(vstar[sure], clear[sure])
        checked += sure.sum()
        vstars.append(vstar)
    assert checked > 4 * 1000
    changed = ground & (vstars[0] != vstars[-1])
    assert changed.sum() > 20                              # the box's shadow did sweep over the ground


@pytest.mark.slow
def test_still_light_given_as_a_zero_move_flickers_zero_and_builds_once(run_dict):
    """A spot and a point light 'moving' by [0, 0, 0]: nothing changes between frames, so every
    scheme's flicker is 0 and each map is built once; moved by a real offset, each frame re-fits
    its view (a map per frame) and the fixed points whose V* changes are left out of the pairs."""
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                      light=[{"type": "spot", "position": [-2.0, -1.0, 3.0], "target": [0.0, 0.0, 0.0], "cutoff": 45},
                             {"type": "point", "position": [-1.5, 0.0, 2.5]}],
                      scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}],
                      map={"resolution": 128, "view": "cube", "filter": ["nearest", "pcf_bilinear"]},
                      motion=[{"frames": 3, "light": "move", "light_offset": [0.0, 0.0, 0.0], "points": 1500,
                               "label": "still"},
                              {"frames": 3, "light": "move", "light_offset": [2.0, 1.0, 0.0], "points": 1500}])
    res = run_dict(cfg)
    still = [r for r in res.rows if r["motion"] == "still"]
    moving = [r for r in res.rows if r["motion"] == "light move"]
    assert len(still) == len(moving) == 2 * 2 * 2
    for r in still:
        assert r["flicker_rate"] == 0 and r["flicker_ever"] == 0 and r["flicker_magnitude"] == 0, r["case"]
        assert r["maps_built"] == 1
    assert all(r["maps_built"] == 3 for r in moving)
    frames = [f for f in _frames(res) if f["frame"] != "0"]
    by = lambda label: [int(f["n_pairs_eligible"]) for f in frames if f["motion"] == label]
    assert min(by("still")) > 100
    # the same points, the same camera: the moving light's pairs leave out the points whose V* changed
    assert sum(by("light move")) < sum(by("still"))


def test_light_move_config_errors_name_the_key():
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    for motion, key in (({"light": "move"}, "motion[0].light_offset"),
                        ({"light": "keyframes"}, "motion[0].light_keys"),
                        ({"light": "keyframes", "light_keys": [{"position": [0, 0, 1]}]}, "motion[0].light_keys"),
                        ({"light": "keyframes", "light_keys": [{"position": [0, 0, 1]}, {"target": [0, 0, 0]}]},
                         "motion[0].light_keys[1]"),
                        ({"light": "keyframes", "light_keys": [{"position": [0, 0, 1]}, {"position": [0, 0, 1],
                                                                                          "aim": [0, 0, 0]}]},
                         "motion[0].light_keys[1].aim"),
                        ({"light": "keyframes", "light_keys": [{"position": [0, 0, 1], "target": [0, 0, 0]},
                                                               {"position": [1, 0, 1]}]}, "motion[0].light_keys"),
                        ({"light": "orbit"}, "motion[0].light")):
        with pytest.raises(ConfigError) as e:
            config.parse(base_config(motion=[motion]), "t.toml")
        assert e.value.key == key, (motion, e.value)
    with pytest.raises(ConfigError) as e:          # a sun cannot move: the path needs a spot or point light
        config.parse(base_config(light=[{"type": "directional", "direction": [0, 0, -1]}],
                                 motion=[{"light": "move", "light_offset": [1, 0, 0]}]), "t.toml")
    assert e.value.key == "motion[0].light" and set(e.value.choices) == {"spot", "point"}
    assert "t.toml" in str(e.value)
    cfg = config.parse(base_config(motion=[{"light": "move", "light_offset": [1, 0, 0]},
                                           {"light": "keyframes", "light_keys": [{"position": [0, 0, 1]},
                                                                                 {"position": [1, 0, 1]}]}]), "t.toml")
    assert [m.label for m in cfg.motion] == ["light move", "light keyframes"]
    assert cfg.motion[1].light_keys == (((0.0, 0.0, 1.0), None), ((1.0, 0.0, 1.0), None))


def test_light_keyframes_interpolate_positions_and_a_spots_aim():
    """Keyframes at frames 0, 2, 4 of 5: frame 1 is halfway between the first two (scaled and moved
    as the scene); without targets a spot keeps its direction, with targets it aims at the
    interpolated target; a directional light stays still."""
    from dsm.experiment import motion
    from dsm.core.types import LightSpec, MotionSpec
    spot = LightSpec("spot", position=(0.0, 0.0, 3.0), target=(1.0, 0.0, 0.0), cutoff=40.0)
    keys = (((0.0, 0.0, 3.0), None), ((2.0, 0.0, 3.0), None), ((2.0, 2.0, 5.0), None))
    s, t = 3.0, np.array([10.0, 0.0, -1.0])
    out = motion.light_path(MotionSpec(frames=5, light="keyframes", light_keys=keys), spot, s, t)
    assert np.allclose(out[1].position, np.array([1.0, 0.0, 3.0]) * s + t)
    assert np.allclose(out[3].position, np.array([2.0, 1.0, 4.0]) * s + t)
    for lf in out:       # direction kept: the target moves with the light
        assert np.allclose(np.subtract(lf.target, lf.position), np.subtract(spot.target, spot.position))
    aimed = tuple((p, (0.0, 0.0, 0.0) if i < 2 else (4.0, 0.0, 0.0)) for i, (p, _) in enumerate(keys))
    out = motion.light_path(MotionSpec(frames=5, light="keyframes", light_keys=aimed), spot, s, t)
    assert np.allclose(out[3].target, np.array([2.0, 0.0, 0.0]) * s + t)
    by_dir = LightSpec("spot", position=(0.0, 0.0, 3.0), direction=(0.0, 0.0, -1.0))
    out = motion.light_path(MotionSpec(frames=5, light="keyframes", light_keys=aimed), by_dir, s, t)
    d = np.asarray(out[3].direction)
    assert out[3].target is None and np.allclose(d / np.linalg.norm(d), np.array([0.0, -1.0, -4.0]) / np.sqrt(17.0))
    sun = LightSpec("directional", direction=(0.0, 0.0, -1.0))
    assert all(lf == sun for lf in motion.light_path(MotionSpec(frames=3, light="move", light_offset=(1, 0, 0)), sun))


def test_motion_with_an_area_light_is_a_config_error(tmp_path, capsys):
    """It ran: its fixed points' V* was one ray to the light's centre, and its row summed the
    frames' counts beside the last frame's penumbra count and errors (n_gt_lit + n_gt_shadowed +
    n_penumbra was not n_receivers)."""
    cfg = base_config(scene=[{"builtin": "plane_box"}],
                      light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}],
                      motion=[{"frames": 2, "camera": "dolly", "offset": [0.0, 0.5, 0.0], "points": 100}])
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "light[0].type", "[[motion]]", "point")
