"""Voxelized shadow volumes (Wyman 2011) and Dou et al. 2014's adaptive voxel choice (section 3.3).

Known answers: the plain voxel test's acne on a lit floor, derived below from the voxel sizes and
the floor's slope in epipolar coordinates; a float64 recomputation of every receiver's voxel
classification on a tilted plane; the adaptive choice's zero acne on planes; a floating plate's
shadow kept but for the columns whose ray passes beside the plate.
"""
import math

import numpy as np
import pytest

from conftest import base_config

H_LIGHT, H_EYE = 6.0, 3.0       # the floor test: light and eye on the floor's normal through the origin


def _case(cfg_dict, kind="vsv", R=64):
    """(scene, setup, view, map, receivers) of the config's first scene and light, by the kit's stages."""
    import dsm.pipeline as pl
    from dsm.config import read as config
    cfg = config.parse(cfg_dict, "<test>")
    sd = pl.load_scene(cfg.scenes[0], cfg.camera_resolution, cfg.camera)
    gb = pl.gbuffer(sd)
    light = sd.lights_for(cfg.lights)[0]
    setup = pl.light_setup(sd, gb, light, "0")
    view = pl.make_view(light, R, pl.points_np(setup.p), sd.bbox, kind, None, sd.sensor, sd.scale)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool))
    smap = pl.store(pl.build_map(sd.scene, view, ()), "float32")
    rx = pl.receivers(view, setup, sd.diagonal)
    return sd, setup, view, smap, rx


def _lookup(table, rx, smap):
    """(V, nearest tap's shape) of one scheme table on the map, as numpy arrays (the config's
    parser: pipeline.scheme_spec, the plugins' parser, knows the shadow-map schemes only)."""
    import dsm.pipeline as pl
    from dsm.config import read as config
    from dsm import schemes
    spec, = config.parse_scheme(table, "<test>", "scheme", schemes.ALL, schemes.PRESETS)
    v, shape = pl.visibility(spec, rx, smap)
    return v.numpy(), shape.numpy()


def _floor_config():
    return base_config(scene=[{"builtin": "plane", "tilt": 0}], camera={
        "resolution": [200, 200], "position": [0, 0, H_EYE], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 60},
        light=[{"type": "point", "position": [0, 0, H_LIGHT]}], map={"resolution": 64, "view": ["vsv"]},
        scheme=[{"name": "vsv"}])


@pytest.fixture(scope="module")
def floor(variant):
    return _case(_floor_config())


def _np(v):
    return np.stack([np.asarray(c, np.float64) for c in (v.x.numpy(), v.y.numpy(), v.z.numpy())], axis=1)


def test_floor_acne_of_the_plain_voxel_test_follows_voxel_size_and_slope(floor):
    """Light and eye on the floor's normal through the origin: every epipolar plane is a vertical
    half-plane and a floor point at radius r has phi = atan(r / h_L) (at the light, from the
    downward axis) and alpha = pi - atan(r / h_E) (at the eye, from the upward axis), whatever its
    theta. The ray through its cell's centre meets the floor at H, and in alpha voxel units
    s_F = s_H + g x, x in [-1/2, 1/2] the receiver's offset from the centre in phi cells and
    g = (d alpha / d phi) (phi cell / alpha voxel), d alpha / d phi = (h_E / (h_E^2 + r^2)) /
    (h_L / (h_L^2 + r^2)) along the floor. With w = frac(s_H) uniform over the cells:
    - centre occupancy (voxel k occluded iff its centre k + 1/2 lies past s_H): acne iff
      floor(w + g x) + 1/2 > w, of probability 1/2 for every g (the two halves of w mirror);
    - hit occupancy (the hit's voxel occluded too): acne iff w + g x >= 0, i.e. x >= -w / g:
      1 - g / 8 for g <= 2, 1/2 + 1 / (2 g) beyond."""
    _, setup, view, smap, rx = floor
    assert setup.v_star.all()                               # nothing shadows the floor
    r = np.hypot(*_np(rx.p_world)[:, :2].T)
    slope = (H_EYE / (H_EYE ** 2 + r ** 2)) / (H_LIGHT / (H_LIGHT ** 2 + r ** 2))
    for alpha in (16, 256):
        g = slope * (view.phi_span / view.resolution) / (view.alpha_span / alpha)
        hit = np.where(g <= 2, 1 - g / 8, 0.5 + 0.5 / g).mean()
        for occupancy, expected in (("centre", 0.5), ("hit", hit)):
            v, _ = _lookup({"name": "vsv", "alpha": alpha, "occupancy": occupancy}, rx, smap)
            assert (v < 0.5).mean() == pytest.approx(expected, abs=0.02), (alpha, occupancy, g.min(), g.max())
    assert 0.2 < (slope * (view.phi_span / 64) / (view.alpha_span / 16)).max() < 0.5    # g <= 2 at 16 voxels
    assert (slope * (view.phi_span / 64) / (view.alpha_span / 256)).min() > 2            # g > 2 at 256


@pytest.mark.slow
def test_floor_acne_of_the_constant_epsilon_follows_its_shift_in_voxels(floor):
    """The epsilon moves the receiver toward the light by delta alpha voxels (delta = s(F) -
    s(F + epsilon l), float64; near the nadir view and light rays are parallel and delta -> 0:
    a constant epsilon does little there). Under the centre occupancy acne iff floor(w + g x - delta)
    + 1/2 > w, i.e. g x >= b(w) - w + delta with b = [w >= 1/2]: per receiver the mean over w of
    clip(1/2 - (b - w + delta) / |g|, 0, 1) (x uniform), w integrated on a grid."""
    sd, _, view, smap, rx = floor
    p = _np(rx.p_world)
    r = np.hypot(*p[:, :2].T)
    light, eye = np.array([0, 0, H_LIGHT]), np.array([0, 0, H_EYE])
    slope = (H_EYE / (H_EYE ** 2 + r ** 2)) / (H_LIGHT / (H_LIGHT ** 2 + r ** 2))
    alpha_of = lambda q: np.arccos(np.clip(((q - eye) @ (light - eye)) / np.linalg.norm(q - eye, axis=1)
                                           / (H_LIGHT - H_EYE), -1, 1))
    w = (np.arange(400) + 0.5) / 400
    b = (w >= 0.5).astype(float)
    for N, K in ((16, 0.03), (256, 0.003), (256, 0.01)):         # g below 1/2, above 2 (w uniform over cells)
        g = slope * (view.phi_span / view.resolution) / (view.alpha_span / N)
        moved = p + K * sd.diagonal * (light - p) / np.linalg.norm(light - p, axis=1, keepdims=True)
        delta = (alpha_of(p) - alpha_of(moved)) / view.alpha_span * N
        expected = np.clip(0.5 - (b[None] - w[None] + delta[:, None]) / g[:, None], 0, 1).mean(axis=1).mean()
        assert expected < 0.45                                   # the epsilon matters here
        v, _ = _lookup({"name": "vsv_epsilon", "alpha": N, "K": K}, rx, smap)
        assert (v < 0.5).mean() == pytest.approx(expected, abs=0.02), (N, K, expected)


def test_adaptive_choice_removes_the_floor_acne_and_needs_the_centre_occupancy(floor):
    """Dou et al.'s F' is H itself on a plane; the voxel chosen (V2 when F' is behind or on its
    centre, else V3 toward the light) has its centre at or before H: lit under the centre
    occupancy. Under the hit occupancy V2 holds H and is occluded: acne where frac(s_H) >= 1/2,
    half of the cells."""
    _, setup, view, smap, rx = floor
    for alpha in (16, 256):
        v, _ = _lookup({"name": "vsv_adaptive", "alpha": alpha}, rx, smap)
        assert (v < 0.5).sum() == 0
        v, _ = _lookup({"name": "vsv_adaptive", "alpha": alpha, "occupancy": "hit"}, rx, smap)
        assert (v < 0.5).mean() == pytest.approx(0.5, abs=0.05)


def test_the_stored_grid_is_the_binary_grid_the_lookup_reads(floor):
    """The plain test of each receiver equals its voxel in the grid expanded by dsm.maps.vsv.voxels
    (cell from floor(u), floor(v); voxel floor(N depth))."""
    from dsm.maps.vsv import grid_bits, voxels
    _, _, view, smap, rx = floor
    grid = voxels(smap.z1.numpy(), view.resolution, 64)
    assert grid.shape == (64, 64, 64) and grid_bits(64, 64) == grid.size
    assert np.all(np.diff(grid.astype(int), axis=2) >= 0)       # a column: lit, then occluded past the hit
    i = np.clip(np.floor(rx.u_map.numpy()).astype(int), 0, 63)
    j = np.clip(np.floor(rx.v_map.numpy()).astype(int), 0, 63)
    k = np.clip(np.floor(rx.depth.numpy().astype(np.float64) * 64).astype(int), 0, 63)
    v, _ = _lookup({"name": "vsv", "alpha": 64}, rx, smap)
    assert np.mean((v >= 0.5) == ~grid[j, i, k]) > 0.999


def _epipolar_np(p, light, eye, up):
    """theta, phi, alpha of points (n, 3) in float64, from the definitions (Dou et al. section 3.3)."""
    a = (eye - light) / np.linalg.norm(eye - light)
    b = up - a * (up @ a)
    b /= np.linalg.norm(b)
    c = np.cross(a, b)
    q = p - light
    theta = np.mod(np.arctan2(q @ c, q @ b), 2 * np.pi)
    phi = np.arccos(np.clip((q @ a) / np.linalg.norm(q, axis=1), -1, 1))
    e = p - eye
    alpha = np.arccos(np.clip((e @ -a) / np.linalg.norm(e, axis=1), -1, 1))
    return theta, phi, alpha, (a, b, c)


def test_tilted_plane_classification_matches_a_float64_recomputation(variant):
    """A 30-degree plane, an off-axis point light and the built-in's camera: each receiver's cell,
    its centre ray's hit on the plane (none beside its 4 x 4 square), the voxels, the plain test
    under both occupancies, the constant epsilon and the adaptive choice recomputed in float64 from
    the definitions; the kit's float32 verdicts agree but for receivers within float32 noise of a
    voxel boundary."""
    light = np.array([1.5, -1.0, 4.0])
    sd, setup, view, smap, rx = _case(base_config(scene=[{"builtin": "plane", "tilt": 30}],
                                                  light=[{"type": "point", "position": light.tolist()}],
                                                  map={"resolution": 64, "view": ["vsv"]},
                                                  scheme=[{"name": "vsv"}]))
    from dsm.maps.vsv import camera_pose
    eye, up = camera_pose(sd.sensor)
    p, n = _np(rx.p_world), _np(rx.n_world)
    theta, phi, alpha, (a, b, c) = _epipolar_np(p, light, eye, up)
    R, N = view.resolution, 128
    dt, dp = view.theta_span / R, view.phi_span / R
    i = np.floor(np.mod(theta - view.theta0, 2 * np.pi) / dt)
    j = np.floor((phi - view.phi0) / dp)
    tc, pc = view.theta0 + (i + 0.5) * dt, view.phi0 + (j + 0.5) * dp
    d = np.cos(pc)[:, None] * a + np.sin(pc)[:, None] * (np.cos(tc)[:, None] * b + np.sin(tc)[:, None] * c)
    t = np.einsum("ij,ij->i", p - light, n) / np.einsum("ij,ij->i", d, n)
    s = lambda x: (_epipolar_np(x, light, eye, up)[2] - view.alpha0) / view.alpha_span * N
    hit = light + d * t[:, None]
    e2 = np.cross(n, [1.0, 0.0, 0.0])                  # the 4 x 4 plane's in-plane axes (tilted about x)
    on_plane = (np.abs(hit[:, 0]) <= 2) & (np.abs(np.einsum("ij,ij->i", hit, e2)) <= 2)
    s_hit = np.where(on_plane, s(hit), np.inf)         # a ray beside the plane: an unoccluded column
    s_rx = s(p)
    eps = 1e-4 * sd.diagonal
    s_prime = s(light + d * (t - eps)[:, None])
    k2 = np.floor(s_prime)
    k_adaptive = np.where(s_prime >= k2 + 0.5, k2, k2 - 1)
    first = {"centre": np.clip(np.floor(s_hit + 0.5), 0, N), "hit": np.clip(np.floor(s_hit), 0, N)}
    to_light = (light - p) / np.linalg.norm(light - p, axis=1, keepdims=True)
    s_eps = s(p + 0.01 * sd.diagonal * to_light)
    checks = [({"name": "vsv_epsilon", "alpha": N, "K": 0.01}, np.clip(np.floor(s_eps), -1, N - 1) < first["centre"]),
              ({"name": "vsv", "alpha": N}, np.floor(s_rx) < first["centre"]),
              ({"name": "vsv", "alpha": N, "occupancy": "hit"}, np.floor(s_rx) < first["hit"]),
              ({"name": "vsv_adaptive", "alpha": N}, np.clip(k_adaptive, -1, N - 1) < first["centre"])]
    assert setup.v_star.all() and len(p) > 10000
    for table, lit64 in checks:
        v, _ = _lookup(table, rx, smap)
        assert np.mean((v >= 0.5) == lit64) > 0.998, table
    assert lit64.all()                                       # the adaptive choice: no acne, in float64 too
    assert 0.4 < 1 - checks[1][1].mean() < 0.6               # the plain test: about half (see the floor test)


def test_floating_plate_keeps_its_shadow(variant):
    """A plate 0.2 above the ground under a point light. A truly shadowed ground point whose
    cell's centre ray hits the plate reads an occluded voxel under the adaptive choice (the plate's
    shadow starts many voxels before the ground along the ray; the choice moves one voxel toward
    the light at most); one whose ray passes beside the plate meets the ground near the point and
    reads lit. So the peter-panning is exactly the shadowed receivers whose column's first hit is
    the ground: the band of one cell along the shadow's outline."""
    sd, setup, view, smap, rx = _case(base_config(scene=[{"builtin": "floating_plate"}], camera={
        "resolution": [192, 192], "position": [1.2, -2.0, 2.2], "target": [0, 0, 0]},
                                                  light=[{"type": "point", "position": [0.5, 0.3, 3.0]}],
                                                  map={"resolution": 128, "view": ["vsv"]},
                                                  scheme=[{"name": "vsv"}]), R=128)
    ground = sd.shape_names.index("ground")
    shadowed = ~setup.v_star
    assert shadowed.sum() > 1000
    for table in ({"name": "vsv_adaptive", "alpha": 256}, {"name": "vsv_adaptive", "alpha": 64}):
        v, tap_shape = _lookup(table, rx, smap)
        peterpan = shadowed & (v >= 0.5)
        assert peterpan.sum() == (shadowed & (tap_shape == ground)).sum(), table
        assert peterpan.mean() / shadowed.mean() < 0.1       # the one-cell band along the outline
        assert not (shadowed & (tap_shape != ground) & (v >= 0.5)).any()


@pytest.mark.slow
def test_plan_pairs_each_view_with_its_own_lookups_and_a_spot_gets_a_grid(run_dict):
    """A VSV grid is read by the vsv lookups only, a depth map by the shadow-map schemes only; a
    spot light with view = ["vsv"] gets its perspective map and a grid over the same cone."""
    from dsm.config import read as config
    from dsm.config import plan
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [64, 64]},
                      light=[{"type": "spot", "position": [2, -2, 4], "target": [0, 0, 0], "cutoff": 35}],
                      map={"resolution": 32, "view": ["vsv"]},
                      scheme=[{"name": "adaptive"}, {"name": "vsv_adaptive", "alpha": 64}, {"name": "vsv"}])
    maps = plan.make(config.parse(cfg, "<test>")).maps
    assert [(m.view, [s.name for s in m.specs]) for m in maps] == [
        ("perspective", ["adaptive"]), ("vsv", ["vsv_adaptive", "vsv"])]
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    rows = {r["scheme"]: r for r in res.rows}
    assert rows["adaptive"]["n_receivers"] == rows["vsv"]["n_receivers"] > 1000
    assert math.isnan(rows["vsv"]["n_acne_resolution"])       # no depth-bias oracle for a binary grid
    assert rows["vsv_adaptive"]["acne_rate"] < rows["vsv"]["acne_rate"]


def test_bad_vsv_parameters_are_config_errors_naming_the_key():
    from dsm.config import read as config
    with pytest.raises(config.ConfigError, match=r"scheme\[0\]\.occupancy.*centre, hit"):
        config.parse(base_config(scheme=[{"name": "vsv", "occupancy": "middle"}]), "<test>")
    for alpha in (0, 65537, 2.5):
        with pytest.raises(config.ConfigError, match=r"scheme\[0\]\.alpha"):
            config.parse(base_config(scheme=[{"name": "vsv_adaptive", "alpha": alpha}]), "<test>")


@pytest.mark.slow
def test_a_moving_camera_rebuilds_the_grid_each_frame_and_schemes_lists_the_lookups(run_dict):
    """A VSV is view-dependent: a camera dolly changes the epipolar frame and ranges, so every
    frame builds its own grid (dsm.experiment.motion compares the view's frame and extents)."""
    from dsm import cli
    cfg = base_config(scene=[{"builtin": "room"}], camera={"resolution": [48, 48]}, light=[{"type": "scene"}],
                      map={"resolution": 32, "view": ["vsv"]}, scheme=[{"name": "vsv_adaptive", "alpha": 64}],
                      motion=[{"frames": 3, "camera": "dolly", "offset": [0.3, 0.0, 0.0], "points": 300}],
                      report={"images": "none"})
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0 and res.rows[0]["maps_built"] == 3
    text = cli.schemes_text()
    assert all(name in text for name in ("vsv ", "vsv_epsilon ", "vsv_adaptive "))


def test_grid_positions_and_rays_round_trip_across_theta_zero(variant):
    """Points whose theta arc straddles theta = 0 (the camera's up): each projects inside the grid,
    the ray of its grid position points at it, and its depth is the fraction of the alpha range,
    alpha recomputed in float64 from its definition (the angle at the eye between E->L and E->P)."""
    import drjit as dr
    import mitsuba as mi
    from dsm.maps.vsv import EpipolarView
    rng = np.random.default_rng(5)
    light, eye, up = np.zeros(3), np.array([0.0, 0.0, -5.0]), np.array([0.0, 1.0, 0.0])
    p = np.stack([rng.uniform(-0.3, 0.3, 2000), rng.uniform(0.5, 1.0, 2000), rng.uniform(-4.0, -1.0, 2000)], 1)
    R = 64
    view = EpipolarView(light, eye, up, p, (p.min(0), p.max(0)), R)
    assert 1.0 < view.theta_span < 1.2          # 2 atan(0.3 / 0.5) and 4 spare cells: the short arc through 0
    pw = mi.Point3f(*(mi.Float(c.astype(np.float32)) for c in p.T))
    u, v, _ = view.project(pw)
    u, v = u.numpy(), v.numpy()
    assert u.min() > 1 and u.max() < R - 1 and v.min() > 1 and v.max() < R - 1     # the spare cells
    _, d = view.ray_at(mi.Float(u), mi.Float(v))
    d = _np(d)
    assert np.abs(d - p / np.linalg.norm(p, axis=1, keepdims=True)).max() < 1e-5
    e = p - eye
    alpha = np.arccos((e @ (light - eye)) / np.linalg.norm(e, axis=1) / 5.0)
    depth = view.depth(pw).numpy()
    assert np.abs(depth - (alpha - view.alpha0) / view.alpha_span).max() < 1e-4
    assert 0 < depth.min() < 0.02 and 0.98 < depth.max() < 1                        # 1 % to spare each side
    dr.eval()


@pytest.mark.slow
def test_filters_and_stored_formats_apply_to_the_voxel_tests(run_dict):
    """Every scheme's filters (the voxel test per tap) and a stored format (the grid's first hits
    quantized over [0, 1] of the alpha range) run on a VSV: the floor's adaptive choice stays
    free of acne in unorm16 (its epsilon, 0.07 voxel here, exceeds the quantization's 0.002),
    the plain test's nearest acne stays 1/2, and a nearest lookup's mean |V - V*| is its error rate."""
    cfg = _floor_config()
    cfg.update(map={"resolution": 64, "view": ["vsv"], "filter": ["nearest", "pcf_bilinear", "pcf_jitter4x4"],
                    "format": ["float32", "unorm16"]},
               scheme=[{"name": "vsv"}, {"name": "vsv_epsilon"}, {"name": "vsv_adaptive"}], report={"images": "none"})
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0 and len(res) == 3 * 3 * 2
    for r in res.rows:
        if r["filter"] == "nearest":
            assert r["mean_abs_error"] == pytest.approx(r["error_rate"], abs=1e-12)
            if r["scheme"] == "vsv_adaptive":
                assert r["n_acne"] == 0, r["format"]
            if r["scheme"] == "vsv":
                assert r["acne_rate"] == pytest.approx(0.5, abs=0.02)


def test_a_lookup_without_its_view_and_a_view_without_its_lookups_are_config_errors():
    from dsm.config import read as config
    with pytest.raises(config.ConfigError, match=r"map\.view: scheme vsv_adaptive reads only a vsv view.*"
                                                 r"valid: paraboloid, dual_paraboloid, cube, vsv"):
        config.parse(base_config(light=[{"type": "point", "position": [0, 0, 3]}],
                                 scheme=[{"name": "vsv_adaptive"}]), "<test>")
    with pytest.raises(config.ConfigError, match=r"map\.view: view vsv is read by its own lookups only "
                                                 r"\(vsv, vsv_epsilon, vsv_adaptive\)"):
        config.parse(base_config(light=[{"type": "point", "position": [0, 0, 3]}],
                                 map={"view": ["cube", "vsv"]}), "<test>")


def test_dsm_tune_refuses_a_vsv_lookup_naming_it():
    from dsm.config import read as config
    from dsm.tune import tuner as tune
    cfg = config.parse(base_config(light=[{"type": "point", "position": [0, 0, 3]}], map={"view": ["vsv"]},
                                   scheme=[{"name": "vsv_epsilon"}], tune={}), "<test>")
    with pytest.raises(config.ConfigError, match=r"scheme\[0\]\.name: vsv_epsilon reads a voxelized shadow volume"):
        tune.parse_tune(cfg)
