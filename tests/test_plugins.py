"""The Mitsuba integrator plugins dsm_error and dsm_shadow: the runner's code, through mi.render."""
import numpy as np
import subprocess
import sys

import pytest

from conftest import ROOT

POINT_XML = ROOT / "tests" / "data" / "point_scene.xml"
SPOT_XML = ROOT / "tests" / "data" / "spot_scene.xml"


def _classes(img):
    from dsm_plugins.integrators import CLASS_LINEAR
    a = np.asarray(img)[..., :3]
    d = ((a[..., None, :] - CLASS_LINEAR[None, None]) ** 2).sum(-1)
    assert d.min(-1).max() < 1e-10                        # every pixel is exactly one class colour
    return np.argmin(d, -1).astype(np.uint8)


@pytest.mark.slow
@pytest.mark.parametrize("xml,scheme,view", [(POINT_XML, {"scheme": "constant", "bias": "1 texel"}, "cube"),
                                             (POINT_XML, {"scheme": "none"}, "dual_paraboloid"),
                                             (SPOT_XML, {"scheme": "slope_scaled"}, "cube"),
                                             (SPOT_XML, {"scheme": "normal_offset", "offset": "1.5 texel"}, "cube"),
                                             # engine presets resolve per light type in the plugin as in the plan
                                             (POINT_XML, {"preset": "bevy"}, "cube"),
                                             (SPOT_XML, {"preset": "filament"}, "cube"),
                                             # the camera reaches a distance-scaled scheme in the plugin too
                                             (SPOT_XML, {"scheme": "distance_normal", "normal_bias": 8.0}, "cube")])
def test_dsm_error_matches_the_runner_pixel_for_pixel(run_dict, xml, scheme, view):
    import mitsuba as mi
    scene = mi.load_file(str(xml))
    props = {"type": "dsm_error", "resolution": 256, "view": view, **scheme}
    img = mi.render(scene, integrator=mi.load_dict(props))
    got = _classes(img)
    W = int(scene.sensors()[0].film().size()[0])
    table = {k: v for k, v in scheme.items() if k != "scheme"}
    res = run_dict({"scene": [{"file": str(xml)}], "camera": {"resolution": [W, W]},
                    "map": {"resolution": 256, "view": view},
                    "scheme": [table if "preset" in scheme else {"name": scheme["scheme"], **table}],
                    "timing": {"repeats": 1}})
    assert len(res) == 1
    want = res.images[res.rows[0]["case"]]
    assert got.shape == want.shape
    np.testing.assert_array_equal(got, want)
    r = res.rows[0]
    assert np.isin(got, (3, 5)).sum() == r["n_acne"] and np.isin(got, (4, 6)).sum() == r["n_peterpan"]
    assert (got == 5).sum() == r["n_acne_resolution"] and (got == 6).sum() == r["n_peterpan_resolution"]


def _box_filtered(tmp_path):
    """The point-light scene with a box pixel filter: each pixel holds only its own samples."""
    import mitsuba as mi
    path = tmp_path / "box.xml"
    path.write_text(POINT_XML.read_text().replace('<film type="hdrfilm">',
                                                  '<film type="hdrfilm">\n            <rfilter type="box"/>'))
    return mi.load_file(str(path))


@pytest.mark.slow
def test_dsm_shadow_with_no_bias_matches_mitsubas_direct_where_the_map_agrees(tmp_path):
    """Same seed, same camera rays: where the map's visibility equals the exact one, dsm_shadow's
    radiance is Mitsuba's direct integrator's (one delta light: no Monte Carlo noise in either),
    while without bias the map disagrees with V* on about half the lit receivers (acne)."""
    import mitsuba as mi
    scene = _box_filtered(tmp_path)
    ours = np.asarray(mi.render(scene, integrator=mi.load_dict(
        {"type": "dsm_shadow", "scheme": "none", "resolution": 2048, "view": "cube", "aovs": True}), spp=1, seed=3))
    direct = np.asarray(mi.render(scene, integrator=mi.load_dict({"type": "direct"}), spp=1, seed=3))
    v, vstar = ours[..., 3], ours[..., 4]
    agree = np.abs(v - vstar) < 1e-6
    lit = vstar > 0.999
    assert (agree & lit).sum() > 2000 and (~agree & lit).sum() > 2000   # acne without bias, agreement elsewhere
    diff = np.abs(ours[..., :3] - direct[..., :3]).max(-1)
    scale = np.abs(direct[..., :3]).max()
    ok = diff[agree] <= 1e-3 * scale
    assert ok.mean() > 0.995, ok.mean()           # a few pixels: Mitsuba's own spawn offset differs


@pytest.mark.slow
def test_dsm_shadow_with_adaptive_bias_matches_direct_almost_everywhere(variant):
    import mitsuba as mi
    scene = mi.load_file(str(POINT_XML))
    ours = np.asarray(mi.render(scene, integrator=mi.load_dict(
        {"type": "dsm_shadow", "scheme": "adaptive", "resolution": 1024}), spp=4, seed=1))
    direct = np.asarray(mi.render(scene, integrator=mi.load_dict({"type": "direct"}), spp=4, seed=1))
    diff = np.abs(ours - direct).max(-1)
    assert (diff <= 1e-3 * np.abs(direct).max()).mean() > 0.98


def test_xml_scene_with_a_dsm_integrator_renders_through_load_file(tmp_path):
    import mitsuba as mi
    text = POINT_XML.read_text().replace(
        '<scene version="3.0.0">',
        '<scene version="3.0.0">\n    <integrator type="dsm_error">\n        <string name="scheme" value="constant"/>\n'
        '        <string name="bias" value="2 texel"/>\n        <integer name="resolution" value="256"/>\n'
        '        <string name="view" value="dual_paraboloid"/>\n    </integrator>')
    path = tmp_path / "with_integrator.xml"
    path.write_text(text)
    scene = mi.load_file(str(path))
    assert "DsmError" in str(scene.integrator())
    got = _classes(mi.render(scene))
    assert (got == 1).sum() > 1000 and (got == 2).sum() > 20   # lit and shadowed receivers are there


# ---------------------------------------------------------------- a plate over a ground quad, built here

PLATE = ((-0.25, 0.45), (-0.35, 0.15), 0.5)           # x range, y range, height of the floating plate
GROUND = 6.0                                           # the ground quad's half size (it fills the view)
OBLIQUE = dict(origin=(1.6, -2.2, 2.6), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0))
TOP_DOWN = dict(origin=(0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
FOV = 40.0


def _mesh(name, verts, faces):
    from dsm.scenes.geometry import make_mesh
    return make_mesh(name, verts, faces)


def _plate_scene(direction, camera=OBLIQUE, size=64, box=False, extra_emitters=None):
    """A ground quad at z = 0 and a one-sided plate floating over it, under a directional light."""
    import mitsuba as mi
    g = GROUND
    (x0, x1), (y0, y1), z = PLATE
    film = {"type": "hdrfilm", "width": size, "height": size}
    if box:
        film["rfilter"] = {"type": "box"}          # each pixel holds only its own samples
    d = {"type": "scene",
         "ground": _mesh("ground", [(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)], [(0, 1, 2), (0, 2, 3)]),
         "plate": _mesh("plate", [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)], [(0, 1, 2), (0, 2, 3)]),
         "light": {"type": "directional", "direction": list(direction)},
         "sensor": {"type": "perspective", "fov": FOV, "film": film,
                    "to_world": mi.ScalarTransform4f().look_at(**{k: list(v) for k, v in camera.items()})}}
    d.update(extra_emitters or {})
    return mi.load_dict(d, optimize=False)


def _camera_rays(camera, u, v):
    """float64 rays of Mitsuba's perspective camera (x field of view, square film) at film
    positions (u, v) in [0, 1]: local direction ((1 - 2u) T, (1 - 2v) T, 1), T = tan(fov / 2),
    in the look-at frame (left = up x dir, up' = dir x left, dir)."""
    o, t, up = (np.asarray(camera[k], np.float64) for k in ("origin", "target", "up"))
    fwd = (t - o) / np.linalg.norm(t - o)
    left = np.cross(up, fwd)
    left /= np.linalg.norm(left)
    up2 = np.cross(fwd, left)
    T = np.tan(np.radians(FOV) / 2)
    d = ((1 - 2 * u)[..., None] * T * left + (1 - 2 * v)[..., None] * T * up2 + fwd)
    return o, d / np.linalg.norm(d, axis=-1, keepdims=True)


def _analytic_kind(camera, u, v):
    """What the camera sees at film positions (u, v): 0 nothing, 1 the plate, 2 the ground in the
    plate's shadow under a light straight down (the hit lies under the plate), 3 lit ground."""
    o, d = _camera_rays(camera, u, v)
    (x0, x1), (y0, y1), z = PLATE
    with np.errstate(divide="ignore", invalid="ignore"):
        tp = (z - o[2]) / d[..., 2]
        tg = -o[2] / d[..., 2]
    pp, pg = o + tp[..., None] * d, o + tg[..., None] * d
    on_plate = (tp > 0) & (pp[..., 0] >= x0) & (pp[..., 0] <= x1) & (pp[..., 1] >= y0) & (pp[..., 1] <= y1)
    on_ground = (tg > 0) & (np.abs(pg[..., 0]) <= GROUND) & (np.abs(pg[..., 1]) <= GROUND)
    under = (pg[..., 0] >= x0) & (pg[..., 0] <= x1) & (pg[..., 1] >= y0) & (pg[..., 1] <= y1)
    return np.where(on_plate, 1, np.where(on_ground, np.where(under, 2, 3), 0))


def test_dsm_error_shadow_count_matches_an_analytic_shadow(variant):
    """Independent of the kit's code: pixels dsm_error calls shadowed (correct shadow +
    peter-panning, i.e. V* = 0) are the pixels whose hit point lies under the plate, counted in
    float64 numpy from the camera model, up to the pixels whose footprint straddles an edge."""
    import mitsuba as mi
    W = 64
    scene = _plate_scene((0.0, 0.0, -1.0), OBLIQUE)
    # the numpy camera is Mitsuba's: same rays through a few film positions
    sensor = scene.sensors()[0]
    uv = np.array([[0.5, 0.5], [0.1, 0.8], [0.93, 0.07], [0.3, 0.6]])
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(uv[:, 0], uv[:, 1]), mi.Point2f(0.5, 0.5))
    _, d = _camera_rays(OBLIQUE, uv[:, 0], uv[:, 1])
    got_d = np.stack([np.asarray(c, np.float64) for c in (ray.d.x, ray.d.y, ray.d.z)], axis=1)
    np.testing.assert_allclose(got_d, d, atol=1e-5)

    classes = _classes(mi.render(scene, integrator=mi.load_dict(
        {"type": "dsm_error", "scheme": "constant", "bias": "1 texel", "resolution": 128})))
    j, i = np.mgrid[0:W, 0:W].astype(np.float64)
    centre = _analytic_kind(OBLIQUE, (i + 0.5) / W, (j + 0.5) / W)
    # 5 x 5 positions over each pixel's footprint, corners included
    s = np.linspace(0.0, 1.0, 5)
    sub = np.stack([_analytic_kind(OBLIQUE, (i + a) / W, (j + b) / W) for a in s for b in s])
    shadow_any, shadow_all = (sub == 2).any(0), (sub == 2).all(0)
    edge = shadow_any & ~shadow_all                     # within one pixel footprint of the shadow's edge
    want = int((centre == 2).sum())
    got = int(np.isin(classes, (2, 4, 6)).sum())
    assert want > 100 and 0 < edge.sum() < want // 2, (want, edge.sum())
    assert abs(got - want) <= edge.sum(), (got, want, edge.sum())
    # pixel by pixel: every pixel off the edge is shadowed exactly when the analytic one is
    shadowed = np.isin(classes, (2, 4, 6))
    np.testing.assert_array_equal(shadowed[~edge], (centre == 2)[~edge])
    # and the receivers are every pixel that sees the plate or the ground
    assert ((classes > 0) == (centre > 0)).all()


def test_dsm_shadow_rim_pixels_sampled_off_centre_stay_lit(variant):
    """spp = 4 samples land anywhere in a pixel, some beyond the receivers at the pixel centres
    that the directional light's map used to be fitted to (their taps clamped, V = 0 at the
    image rim). Where exact visibility is lit, no rim pixel may read less than lit."""
    import mitsuba as mi
    W = 64
    scene = _plate_scene((0.35, 0.25, -1.0), TOP_DOWN, box=True)
    integrator = mi.load_dict({"type": "dsm_shadow", "scheme": "constant", "bias": "2 texel", "resolution": 128,
                               "aovs": True})
    img = np.asarray(mi.render(scene, integrator=integrator, spp=4, seed=1))
    v, vstar = img[..., 3], img[..., 4]
    rim = np.zeros((W, W), bool)
    rim[0] = rim[-1] = rim[:, 0] = rim[:, -1] = True
    lit = vstar > 1 - 1e-6
    assert (rim & lit).sum() > 200                      # the rim is lit ground
    assert not (rim & lit & (v < 1e-6)).any()           # the issue: V = 0 on a lit rim
    assert not (rim & lit & (v < 1 - 1e-6)).any(), np.argwhere(rim & lit & (v < 1 - 1e-6))[:5]
    assert (vstar < 0.5).sum() > 10                     # the plate's shadow is in view
    # the map covers every pixel's footprint by itself (not only through "outside = lit")
    from dsm_plugins.integrators import corner_points
    lp = integrator._prep["lights"][0]
    corners = corner_points(scene, scene.sensors()[0], W, W, lp.light.direction)
    assert len(corners) == (W + 1) ** 2
    assert lp.view.inside(mi.Point3f(*(corners[:, k].astype(np.float32) for k in range(3)))).numpy().all()


@pytest.mark.parametrize("plugin", ["dsm_error", "dsm_shadow"])
def test_a_scene_updated_through_traverse_renders_as_a_fresh_integrator_would(plugin):
    """Mitsuba does not tell an integrator that mi.traverse(scene) + params.update() moved a
    shape: the plugin must not keep the map of the scene as it was."""
    import mitsuba as mi
    scene = _plate_scene((0.35, 0.25, -1.0), OBLIQUE, box=True)
    props = {"type": plugin, "scheme": "constant", "bias": "2 texel", "resolution": 128}
    if plugin == "dsm_shadow":
        props["aovs"] = True
    kept = mi.load_dict(props)
    before = np.asarray(mi.render(scene, integrator=kept, spp=1, seed=2))
    again = np.asarray(mi.render(scene, integrator=kept, spp=1, seed=2))
    np.testing.assert_array_equal(before, again)                  # unchanged scene: same image
    params = mi.traverse(scene)
    moved = np.asarray(params["plate.vertex_positions"]).copy().reshape(-1, 3)
    moved[:, 0] -= 0.4
    moved[:, 2] += 0.3
    params["plate.vertex_positions"] = mi.Float(moved.ravel())
    params.update()
    after = np.asarray(mi.render(scene, integrator=kept, spp=1, seed=2))
    fresh = np.asarray(mi.render(scene, integrator=mi.load_dict(props), spp=1, seed=2))
    assert np.abs(fresh - before).max() > 0.1                    # the move shows in the image
    np.testing.assert_array_equal(after, fresh)


def test_light_out_of_range_names_the_scene_emitters(variant):
    import mitsuba as mi
    from dsm import ConfigError
    scene = _plate_scene((0.0, 0.0, -1.0), OBLIQUE,
                         extra_emitters={"lamp": {"type": "point", "position": [0.5, -1.0, 2.0]}})
    for plugin in ("dsm_error", "dsm_shadow"):
        with pytest.raises(Exception) as info:
            mi.render(scene, integrator=mi.load_dict({"type": plugin, "light": 7, "resolution": 64}))
        err = info.value
        while err is not None and not isinstance(err, ConfigError):   # mi.render chains it (drjit.custom)
            err = err.__cause__ or err.__context__
        assert err is not None, info.value
        line = str(err)
        assert "\n" not in line
        assert line.startswith(f'<integrator type="{plugin}">: light: 7 is out of range; the scene\'s '
                               "point/spot/directional emitters are 0: "), line
        assert "directional towards (0, 0, -1)" in line and "point at (0.5, -1, 2)" in line, line
        assert "1: " in line and "2: " not in line
    # the last emitter is a valid index
    img = mi.render(scene, integrator=mi.load_dict({"type": "dsm_error", "light": 1, "resolution": 64}))
    assert np.asarray(img).shape[:2] == (64, 64)


VALID_SCHEMES = ("none, constant, slope_scaled, normal_angle, normal_offset, combined, receiver_plane, adaptive, midpoint, "
                 "dual, second_depth, adaptive_tap, distance_normal")


@pytest.mark.parametrize("props,line", [
    ({"scheme": "foo"}, f"scheme: unknown value 'foo' (valid: {VALID_SCHEMES})"),
    ({"resolution": -1}, "resolution: must be >= 1, got -1"),
    ({"view": "sphere"}, "view: unknown value 'sphere' (valid: paraboloid, dual_paraboloid, cube)"),
    ({"scheme": "constant", "bias": "2 parsecs"}, "bias: unknown unit 'parsecs' in '2 parsecs' (valid: world, texel, range)"),
    ({"scheme": "constant", "colour": "red"}, "colour: unknown property (valid: scheme, resolution, view, filter, "
                                              "format, light, seed, area, samples, bias)"),
    ({"aovs": True}, "aovs: unknown property (valid: scheme, resolution, view, filter, format, light, seed, area, "
                     "samples, K)"),
    ({"light": -1}, "light: must be >= 0, got -1"),
])
def test_a_bad_property_reads_as_one_line_naming_it(props, line):
    import mitsuba as mi
    with pytest.raises(Exception) as info:
        mi.load_dict({"type": "dsm_error", **props})
    text = str(info.value)
    want = f'<integrator type="dsm_error">: {line}'
    assert text.endswith("ConfigError: " + want), text        # after Mitsuba's "failed to instantiate ...: "
    assert "Traceback" not in text and "\n" not in text, text


@pytest.mark.parametrize("element,line", [
    ('<string name="scheme" value="foo"/>', f"scheme: unknown value 'foo' (valid: {VALID_SCHEMES})"),
    ('<integer name="resolution" value="-1"/>', "resolution: must be >= 1, got -1"),
    ('<string name="aovs" value="maybe"/>', "aovs: expected a boolean, got 'maybe' (valid: true, false)"),
    ('<string name="scheme" value="constant"/><string name="bias" value="2 parsecs"/>',
     "bias: unknown unit 'parsecs' in '2 parsecs' (valid: world, texel, range)"),
])
def test_a_bad_property_in_xml_reads_as_one_line_naming_it(tmp_path, element, line):
    import mitsuba as mi
    text = POINT_XML.read_text().replace(
        '<scene version="3.0.0">', f'<scene version="3.0.0">\n    <integrator type="dsm_shadow">{element}</integrator>')
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(Exception) as info:
        mi.load_file(str(path))
    msg = str(info.value)
    assert msg.endswith(f'ConfigError: <integrator type="dsm_shadow">: {line}'), msg
    assert "Traceback" not in msg and "\n" not in msg, msg


@pytest.mark.parametrize("value,want", [(True, True), (False, False), ("true", True), ("false", False),
                                        ("False", False), ("1", True), ("0", False), (1, True), (0, False)])
def test_aovs_reads_booleans_as_booleans(value, want):
    import mitsuba as mi
    integrator = mi.load_dict({"type": "dsm_shadow", "aovs": value})
    assert integrator.aov_names() == (["dsm.V", "dsm.Vstar"] if want else [])


def test_aovs_from_xml_boolean(tmp_path):
    import mitsuba as mi
    for value, names in (("false", []), ("true", ["dsm.V", "dsm.Vstar"])):
        scene = mi.load_string(POINT_XML.read_text().replace(
            '<scene version="3.0.0">',
            f'<scene version="3.0.0"><integrator type="dsm_shadow"><boolean name="aovs" value="{value}"/>'
            '</integrator>'))
        assert scene.integrator().aov_names() == names
    for bad in ("maybe", 2, "yes please"):
        with pytest.raises(Exception, match=r"aovs: expected a boolean, got .* \(valid: true, false\)"):
            mi.load_dict({"type": "dsm_shadow", "aovs": bad})


def test_bad_plugin_properties_name_the_property_and_the_choices(variant):
    import mitsuba as mi
    from dsm import ConfigError
    with pytest.raises(Exception, match="view: unknown value 'sphere'.*cube"):
        mi.load_dict({"type": "dsm_error", "view": "sphere"})
    with pytest.raises(Exception, match="scheme: unknown value 'magic'.*adaptive"):
        mi.load_dict({"type": "dsm_shadow", "scheme": "magic"})
    with pytest.raises(Exception, match="bias: unknown unit"):
        mi.load_dict({"type": "dsm_shadow", "scheme": "constant", "bias": "2 parsecs"})
    with pytest.raises(Exception, match="name: unknown property; the scheme is given as `scheme`"):
        mi.load_dict({"type": "dsm_shadow", "name": "constant"})
    assert issubclass(ConfigError, Exception)
    # the base class's own properties stay the base class's
    assert mi.load_dict({"type": "dsm_shadow", "hide_emitters": True}).opts.spec.name == "adaptive"


@pytest.mark.slow
def test_the_plugins_under_an_unsupported_variant_say_which_are(tmp_path):
    """Under scalar_rgb or a spectral variant a dsm integrator is refused when loaded, one line
    naming the variants dsm supports (it failed with TypeErrors deep in a render)."""
    code = ("import mitsuba as mi, sys; mi.set_variant(sys.argv[1]); import dsm\n"
            "try:\n    mi.load_dict({'type': 'dsm_error'})\n"
            "except Exception as e:\n    print(str(e).strip().splitlines()[-1])\n")
    for v in ("scalar_rgb", "llvm_ad_spectral"):
        p = subprocess.run([sys.executable, "-c", code, v], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr[-800:]
        assert f"variant {v} is not supported" in p.stdout and "llvm_ad_rgb, cuda_ad_rgb" in p.stdout, p.stdout
