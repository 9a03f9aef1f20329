"""Screen-space contact shadows (dsm.contact) against a march derived by hand in numpy float64."""

import math

import numpy as np
import pytest

import dsm
import dsm.pipeline as pl
from conftest import ROOT, base_config
from dsm.contact import march as contact
from dsm.core import record
from dsm.core.types import ConfigError, ContactSpec, Length, LightSpec

ROOT_DATA = ROOT / "tests" / "data"
W, H = 128, 96
GAP, LENGTH, STEPS, THICK = 0.15, 0.3, 8, 0.08
CAM_O, CAM_T, FOV = np.array([3.0, -5.0, 4.0]), np.zeros(3), 40.0     # the floating_plate built-in's camera
L = np.array([0.8, -0.8, -1.0]) / np.linalg.norm([0.8, -0.8, -1.0])    # the shadow falls toward the camera


def camera_frame():
    """Mitsuba's look_at frame (left = up x dir, up' = dir x left) and the half-angle tangents."""
    f = (CAM_T - CAM_O) / np.linalg.norm(CAM_T - CAM_O)
    left = np.cross([0.0, 0.0, 1.0], f)
    left /= np.linalg.norm(left)
    up = np.cross(f, left)
    tx = math.tan(math.radians(FOV) / 2)
    return f, left, up, tx, tx * H / W


def first_hit(d):
    """(t, point, on plate) of rays CAM_O + t d (n, 3), d with unit forward component: plate z = GAP
    (|x|, |y| <= 0.75), else ground z = 0 (|x|, |y| <= 4); t = inf on a miss."""
    t_plate = (GAP - CAM_O[2]) / d[:, 2]
    p_plate = CAM_O + t_plate[:, None] * d
    on_plate = (np.abs(p_plate[:, :2]) <= 0.75).all(1)
    t_ground = -CAM_O[2] / d[:, 2]
    p_ground = CAM_O + t_ground[:, None] * d
    on_ground = (np.abs(p_ground[:, :2]) <= 4.0).all(1)
    t = np.where(on_plate, t_plate, np.where(on_ground, t_ground, np.inf))
    return t, np.where(on_plate[:, None], p_plate, p_ground), on_plate


def pixel_rays():
    """Per pixel (y * W + x) the ray through its centre, scaled to a unit forward component."""
    f, left, up, tx, ty = camera_frame()
    pix = np.arange(W * H)
    sx, sy = (pix % W + 0.5) / W, (pix // W + 0.5) / H
    return f + np.outer((1 - 2 * sx) * tx, left) + np.outer((1 - 2 * sy) * ty, up)


def hand_march(p, to_light=None, reach=None):
    """Per receiver (rows of p): occluded by the hand march toward the light (``to_light`` per receiver,
    default the sun's; samples at ``reach`` or beyond left out), and ambiguous (a sample within float32's
    reach of a pixel border, of the thickness or of the buffer, or on a pixel whose centre ray grazes
    the plate's edge)."""
    to_light = -L if to_light is None else to_light
    reach = np.full(len(p), np.inf) if reach is None else reach
    f, left, up, tx, ty = camera_frame()
    z_b, _, _ = first_hit(pixel_rays())            # the depth buffer: t is the view depth (unit forward)
    d = pixel_rays()
    edge = np.zeros(W * H, bool)                   # centre rays within 1e-4 of the plate's rim
    p_plate = CAM_O + ((GAP - CAM_O[2]) / d[:, 2])[:, None] * d
    edge |= np.abs(np.abs(p_plate[:, :2]).max(1) - 0.75) < 1e-4
    occ = np.zeros(len(p), bool)
    amb = np.zeros(len(p), bool)
    for k in range(1, STEPS + 1):
        t = LENGTH * k / STEPS
        s = p + to_light * t                       # toward the light
        q = s - CAM_O
        z = q @ f
        x = (0.5 - 0.5 * (q @ left) / (z * tx)) * W
        y = (0.5 - 0.5 * (q @ up) / (z * ty)) * H
        inside = (x >= 0) & (x < W) & (y >= 0) & (y < H) & (t < reach)
        amb |= np.abs(t - reach) < 1e-5
        idx = np.clip(np.floor(y), 0, H - 1).astype(int) * W + np.clip(np.floor(x), 0, W - 1).astype(int)
        behind = z - z_b[idx]
        hit = inside & (behind > 0) & (behind < THICK)
        occ |= hit
        near = lambda a: np.abs(a - np.round(a)) < 2e-4     # float32 reaches ~1e-5 px
        amb |= near(x) | near(y) | (inside & ((np.abs(behind) < 2e-5) | (np.abs(behind - THICK) < 2e-5)
                                              | edge[idx]))
    return occ, amb


def sun_on_plate(resolution: int):
    """The floating plate at GAP (camera W x H) under the sun L: scene, G-buffer, light set-up and
    an R x R map's view (test_contact_presets uses it too)."""
    sd = pl.load_scene(pl.scene_spec({"builtin": "floating_plate", "gap": GAP}), (W, H))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=tuple(L)), "sun")
    return sd, gb, setup, pl.make_view(setup.light, resolution, pl.points_np(setup.p), sd.bbox)


@pytest.fixture(scope="module")
def plate():
    """The floating plate at GAP (camera W x H), its setup, a 512 map's view and receivers."""
    sd, gb, setup, view = sun_on_plate(512)
    smap = pl.store(pl.build_map(sd.scene, view, ()), "float32")
    rx = pl.receivers(view, setup, sd.diagonal)
    return sd, gb, setup, smap, rx


def test_depth_buffer_projects_each_hit_to_its_own_pixel(plate):
    sd, gb, setup, smap, rx = plate
    t, p_hand, _ = first_hit(pixel_rays())
    assert np.array_equal(np.isfinite(t), gb.hit)
    assert np.abs(pl.points_np(gb.p)[gb.hit] - p_hand[gb.hit]).max() < 1e-5    # the frame derived by hand
    db = contact.depth_buffer(gb)
    assert np.allclose(db.depth.numpy()[gb.hit], t[gb.hit], rtol=1e-5)


def test_plate_recovered_pixels_are_the_hand_march(plate):
    """Under a plate at a gap smaller than the march, jitter 0: the occluded receivers are those with
    a sample behind the depth buffer by less than the thickness, and the recovered ones are the
    peter-panned among them."""
    sd, gb, setup, smap, rx = plate
    spec = ContactSpec(Length(LENGTH, "world"), STEPS, Length(THICK, "world"), 0.0)
    occ = contact.march(contact.depth_buffer(gb), rx, spec).numpy().astype(bool)
    _, p_rx, on_plate = first_hit(pixel_rays()[setup.pixels])
    hand, amb = hand_march(p_rx)
    assert amb.mean() < 0.01
    assert np.array_equal(occ[~amb], hand[~amb])
    under = hand & ~on_plate & ~setup.v_star                  # ground in the plate's shadow, seen by the march
    assert under.sum() > 100                                  # the plate's top is what the samples lie behind
    bias = pl.scheme_spec({"name": "constant", "bias": 0.3})  # beyond the plate's 0.23 above the ground along l
    v = pl.visibility(bias, rx, smap)[0].numpy()
    m = contact.case_metrics(v, setup.v_star, occ)
    lit = v >= 0.5
    assert m["n_contact_recovered"] == int((~setup.v_star & lit & occ).sum())
    assert m["n_contact_recovered"] >= int((~setup.v_star & lit & hand & ~amb).sum()) > 100
    assert m["n_contact_false"] == int((setup.v_star & lit & occ).sum())
    n_pp_after = int((~setup.v_star & lit & ~occ).sum())
    assert m["n_contact_missed"] == n_pp_after
    assert m["contact_peterpan_rate"] == pytest.approx(n_pp_after / int((~setup.v_star).sum()))


def test_toward_a_point_light_the_samples_stop_at_it(plate):
    """A point light under the plate's corner (0.05 above the ground, the plate at 0.15): from the
    ground beside it, samples past the light rise to the plate and would find it; the march stops at
    the light, as the hand march does."""
    sd, gb = plate[0], plate[1]
    light = np.array([0.6, -0.6, 0.05])
    setup = pl.light_setup(sd, gb, LightSpec("point", position=tuple(light)), "point")
    view = pl.make_view(setup.light, 64, pl.points_np(setup.p), sd.bbox, "cube")
    rx = pl.receivers(view, setup, sd.diagonal)
    spec = ContactSpec(Length(LENGTH, "world"), STEPS, Length(THICK, "world"), 0.0)
    occ = contact.march(contact.depth_buffer(gb), rx, spec, light_world=light).numpy().astype(bool)
    _, p_rx, _ = first_hit(pixel_rays()[setup.pixels])
    reach = np.linalg.norm(light - p_rx, axis=1)
    hand, amb = hand_march(p_rx, (light - p_rx) / reach[:, None], reach)
    unclamped, amb2 = hand_march(p_rx, (light - p_rx) / reach[:, None])
    # rays grazing toward a light 0.05 above the ground keep samples within float32 reach of it: more ties
    assert amb.mean() < 0.03 and np.array_equal(occ[~amb], hand[~amb])
    assert (unclamped & ~hand & ~amb2).sum() > 10          # what stopping at the light leaves out


def hidden_scene(with_hider: bool):
    """Ground; a caster plate 0.2 above it; (with_hider) a smaller plate at height 2 over the caster
    hiding it from a camera straight above; the sun at 45 degrees from -x."""
    import mitsuba as mi
    from dsm.scenes.camera import look_at_sensor
    from dsm.scenes.geometry import make_mesh, quad
    d = {"type": "scene", "ground": make_mesh("ground", *quad([0, 0, 0], [4, 0, 0], [0, 4, 0])),
         "caster": make_mesh("caster", *quad([0, 0, 0.2], [0.5, 0, 0], [0, 0.5, 0])),
         "sensor": look_at_sensor((0, 0, 5), (0, 0, 0), (0, 1, 0), 40.0, 128, 128)}
    if with_hider:
        d["hider"] = make_mesh("hider", *quad([0, 0, 2.0], [0.32, 0, 0], [0, 0.32, 0]))
    return pl.scene_from_mitsuba(mi.load_dict(d, optimize=False))


@pytest.mark.parametrize("with_hider", [True, False])
def test_a_caster_hidden_behind_a_receiver_is_a_miss(with_hider):
    """The caster's shadow on visible ground (x in (0.54, 0.7), |y| < 0.3; the hider's shadow lies
    beyond x = 1.68): hidden behind the hider's top (a receiver), the march misses it; with the
    hider gone the same receivers are recovered."""
    sd = hidden_scene(with_hider)
    gb = pl.gbuffer(sd)
    caster = sd.shape_names.index("caster")
    assert (gb.shape.numpy()[gb.hit] == caster).any() != with_hider     # hidden: no pixel of it
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=(1 / math.sqrt(2), 0.0, -1 / math.sqrt(2))),
                           "sun")
    view = pl.make_view(setup.light, 512, pl.points_np(setup.p), sd.bbox)
    smap = pl.store(pl.build_map(sd.scene, view, ()), "float32")
    rx = pl.receivers(view, setup, sd.diagonal)
    p = pl.points_np(setup.p)
    region = (p[:, 2] < 1e-3) & (p[:, 0] > 0.56) & (p[:, 0] < 0.68) & (np.abs(p[:, 1]) < 0.28)
    assert region.sum() > 20 and not setup.v_star[region].any()      # shadowed by the caster only
    v = pl.visibility(pl.scheme_spec({"name": "constant", "bias": 0.4}), rx, smap)[0].numpy()
    assert (v[region] >= 0.5).all()                                   # the bias peter-pans them all
    spec = ContactSpec(Length(0.5, "world"), 16, Length(0.1, "world"), 0.0)
    occ = contact.march(contact.depth_buffer(gb), rx, spec).numpy().astype(bool)
    m = contact.case_metrics(v[region], setup.v_star[region], occ[region])
    if with_hider:
        assert m["n_contact_recovered"] == 0 and m["n_contact_missed"] == region.sum()
    else:
        assert m["n_contact_recovered"] > 0.9 * region.sum()


def test_jitter_moves_samples_back_within_a_step(plate):
    sd, gb, setup, smap, rx = plate
    spec = ContactSpec(Length(LENGTH, "world"), STEPS, Length(THICK, "world"), 0.5)
    ts = np.stack([t.numpy() for t in contact.sample_distances(spec, LENGTH, rx, 7)])
    k = np.arange(1, STEPS + 1)[:, None]
    back = k - ts * STEPS / LENGTH                           # each receiver's jitter, the same on every step
    assert np.allclose(back, back[0], atol=1e-4)
    assert back.min() >= 0 and back.max() < 0.5 and back.std() > 0.1


def test_run_writes_the_contact_group_only_when_asked(run_dict):
    cfg = base_config(scene=[{"builtin": "floating_plate", "gap": GAP}], camera={"resolution": [W, H]},
                      scheme=[{"name": "constant", "bias": [0.0, 0.3]}], map={"resolution": 256},
                      light=[{"type": "directional", "direction": L.tolist()}])
    plain = run_dict(cfg, "plain", report=True)
    assert all(not (set(r) & record.GROUPS["contact"]) for r in plain.rows)
    cfg["contact"] = {"length": LENGTH, "steps": STEPS, "thickness": THICK}
    with_c = run_dict(cfg, "contact", report=True)
    for a, b in zip(plain.rows, with_c.rows):
        assert a["n_acne"] == b["n_acne"] and a["n_peterpan"] == b["n_peterpan"]     # the scheme's own numbers
        assert set(record.GROUPS["contact"]) <= set(b)
        assert b["n_contact_missed"] == b["n_peterpan"] - b["n_contact_recovered"]
    assert with_c.rows[1]["n_contact_recovered"] > 0
    assert with_c.rows[1]["contact_error_rate"] < with_c.rows[1]["error_rate"]
    for r in with_c.rows:       # the error after: acne gains the false shadows, peter-pan loses the recovered
        after = r["n_acne"] + r["n_contact_false"] + r["n_peterpan"] - r["n_contact_recovered"]
        assert r["contact_error_rate"] == pytest.approx(after / r["n_receivers"])
        from PIL import Image
        from dsm.report.sections import contact_images
        from dsm.report import figures
        img = np.asarray(Image.open(with_c.out / "images" / figures.image_folder(r) / f"{r['case']}_contact.png").convert("RGB"))
        count = lambda k: int((img.reshape(-1, 3) == contact_images.CONTACT_COLORS[k]).all(1).sum())
        assert (count(3), count(4), count(5)) == (r["n_contact_recovered"], r["n_contact_false"],
                                                  r["n_contact_missed"])
    table = (with_c.out / "table.md").read_text()
    assert "## Contact shadows" in table and "## Contact shadows" not in (plain.out / "table.md").read_text()


@pytest.mark.parametrize("table, key", [({"steps": 0}, "contact.steps"), ({"steps": 300}, "contact.steps"),
                                        ({"jitter": 1.5}, "contact.jitter"), ({"length": 0}, "contact.length"),
                                        ({"length": "2 furlong"}, "contact.length"),
                                        ({"thickness": -1}, "contact.thickness"), ({"steps": [4, 8]}, "contact.steps"),
                                        ({"march": 3}, "contact.march")])
def test_bad_contact_values_are_config_errors(table, key):
    with pytest.raises(ConfigError) as e:
        dsm.parse_config(base_config(contact=table), "<t>")
    assert e.value.key == key and "\n" not in str(e.value)


def test_bevy_preset_is_its_source_values():
    cfg = dsm.parse_config(base_config(contact={"preset": "bevy"}), "<t>")
    assert cfg.contact == ContactSpec(Length(0.3, "world"), 16, Length(0.1, "world"), 0.0)
    for table, key in (({"preset": "unreal"}, "contact.preset"), ({"preset": "bevy", "steps": 4}, "contact.steps")):
        with pytest.raises(ConfigError) as e:
            dsm.parse_config(base_config(contact=table), "<t>")
        assert e.value.key == key


def test_largest_bias_within_the_tolerance():
    """scripts/contact_bias.py: the largest bias whose pooled error is within 1.1x the sweep's minimum."""
    import importlib.util
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("contact_bias", ROOT / "scripts" / "contact_bias.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    errors = {1.0: (0.010, 0.5), 2.0: (0.0100, 0.020), 4.0: (0.0105, 0.021), 8.0: (0.0111, 0.022), 16.0: (0.02, 0.03)}
    assert mod.largest_within(errors, 0) == (4.0, 0.010)        # 0.0111 > 1.1 x 0.010
    assert mod.largest_within(errors, 1) == (8.0, 0.020)        # 0.022 <= 1.1 x 0.020


def test_contact_and_shrink_enter_the_case_keys_only_when_asked():
    from dsm.config import plan
    from dsm.experiment import resume
    cfg = dsm.parse_config(base_config(), "<t>")
    keys = resume.case_keys(cfg, plan.make(cfg), "v")
    with_c = dsm.parse_config(base_config(contact={"steps": 4}), "<t>")
    assert keys != resume.case_keys(with_c, plan.make(with_c), "v")
    again = dsm.parse_config(base_config(), "<t>")
    assert keys == resume.case_keys(again, plan.make(again), "v")


def test_contact_without_a_perspective_camera_is_refused_before_work(tmp_path):
    """An XML scene's own orthographic sensor (no [camera] resolution, so it is kept)."""
    xml = (ROOT_DATA / "spot_scene.xml").read_text().replace('<sensor type="perspective">\n        <float name="fov" value="45"/>',
                                                            '<sensor type="orthographic">')
    path = tmp_path / "ortho.xml"
    path.write_text(xml)
    for extra, key in (({"contact": {"steps": 4}}, "contact"),
                       ({"scheme": [{"name": "distance_normal"}]}, "scheme")):
        with pytest.raises(ConfigError) as e:
            pl.prepare(base_config(scene=[{"file": str(path)}], map={"resolution": 32}, camera={}, **extra))
        assert e.value.key == key and "perspective" in str(e.value)
