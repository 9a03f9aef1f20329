"""Area lights: the Monte Carlo reference against an analytic visible fraction, the adaptive
sampler's spending and early stops, PCSS's penumbra estimate against similar triangles, point
lights' reference cost unchanged, soft metrics by hand, configs and a run end to end."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np

import pytest

from conftest import MESHES, base_config
from dsm import pipeline, schemes
from dsm.config import read as config
from dsm.config.read import ConfigError
from dsm.core.types import LightSpec
from dsm.lights import area_surface
from dsm.maps import lookup
from dsm.maps.receiver import Receiver
from dsm.scenes import geometry as scene_geometry
from dsm.truth import area, intervals, metrics

# the analytic scene: square light (side A, height H) above a square occluder (side B, height Hs)
A, H, B, HS = 1.0, 4.0, 1.0, 2.0
G, HALF = 100, 2.5          # receivers: a G x G grid of ground points over [-HALF, HALF]^2


def _quad(z, half):
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    return scene_geometry.make_mesh("quad", v, np.array([[0, 1, 2], [0, 2, 3]]))


def _analytic(q):
    """Visible fraction from ground points q (n, 2): the occluder projects from q onto the light's
    plane as a square of side B H / Hs centred at q (1 - H / Hs); V = 1 - overlap / A^2."""
    c, s = q * (1 - H / HS), B * H / HS
    ov = [np.clip(np.minimum(c[:, k] + s / 2, A / 2) - np.maximum(c[:, k] - s / 2, -A / 2), 0, None) for k in (0, 1)]
    return 1 - ov[0] * ov[1] / A ** 2


def _region(v):
    return np.where(v <= 0, 0, np.where(v >= 1, 2, 1))


@pytest.fixture(scope="module")
def analytic_scene(variant):
    scene = mi.load_dict({"type": "scene", "ground": _quad(0.0, 6.0), "occluder": _quad(HS, B / 2)})
    xs = np.linspace(-HALF, HALF, G)
    X, Y = np.meshgrid(xs, xs)
    q = np.stack([X.ravel(), Y.ravel()], 1)
    # ground points hit from below (nothing in the way), their normal facing the light
    o = mi.Point3f(mi.Float(q[:, 0]), mi.Float(q[:, 1]), mi.Float(np.full(len(q), -1.0)))
    si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0, 0, 1)))
    assert si.is_valid().numpy().all()
    n = dr.zeros(mi.Vector3f, len(q)) + mi.Vector3f(0, 0, 1)
    light = LightSpec("area", position=(0.0, 0.0, H), direction=(0.0, 0.0, -1.0), shape="rectangle", size=(A,))
    # a receiver's footprint: the grid cell around it; its region is ambiguous where the exact
    # regions at the cell's corners differ from its own
    step = xs[1] - xs[0]
    corners = [_region(_analytic(q + np.array([dx, dy]) * step / 2)) for dx in (-1, 1) for dy in (-1, 1)]
    straddles = np.any([c != _region(_analytic(q)) for c in corners], axis=0)
    return scene, si, n, area_surface.geometry(light), _analytic(q), straddles


def test_student_t_quantiles_match_the_tables():
    """Against printed tables of Student's t (two-sided 99 % and 95 %)."""
    for p, dof, table in ((0.995, 7, 3.499), (0.995, 15, 2.947), (0.975, 1, 12.706), (0.975, 30, 2.042)):
        assert abs(intervals.t_quantile(p, dof) - table) < 5e-4
    # a zero count certifies f <= tolerance once (1 - tol)^n <= 1 - c: n >= ln(0.01) / ln(0.99) = 458.2
    assert intervals.samples_to_certify(0.01, 0.99) == 459
    assert abs(intervals.zero_count_bound(459, 0.99) - (1 - 0.01 ** (1 / 459))) < 1e-15


def test_student_t_quantile_is_remembered_per_p_and_dof():
    """A remembered quantile is the fresh computation's float64 answer for its own (p, dof), whatever was
    asked between (dof = 1 is Cauchy's: tan(pi (p - 1/2)))."""
    asked = [(0.995, 1), (0.975, 4), (0.995, 1), (0.975, 1), (0.975, 4)]
    for p, dof in asked:
        assert intervals.t_quantile(p, dof) == intervals.t_quantile.__wrapped__(p, dof)
    assert abs(intervals.t_quantile(0.995, 1) - math.tan(math.pi * 0.495)) < 1e-6 * math.tan(math.pi * 0.495)
    assert abs(intervals.t_quantile(0.975, 1) - math.tan(math.pi * 0.475)) < 1e-6 * math.tan(math.pi * 0.475)


def test_zero_count_bound_holds_for_stratified_samples():
    """A region of area f in the unit square (a corner strip, the case of a receiver at an umbra's
    edge) is missed by all n jittered samples no more often than by n independent ones:
    P = prod(1 - f_i) <= (1 - f)^n, counted over 20000 trials (numpy)."""
    rng = np.random.default_rng(3)
    n, f = 64, 0.02
    a = 8
    miss = 0
    trials = 20000
    for _ in range(trials // 1000):
        u = (np.arange(n) % a + rng.random((1000, n))) / a
        miss += int((u.min(1) >= f).sum())          # the strip x < f is hit by no sample
    p_indep = (1 - f) ** n
    assert miss / trials <= p_indep + 3 * np.sqrt(p_indep * (1 - p_indep) / trials)


@pytest.mark.slow
def test_reference_intervals_mean_what_they_say(analytic_scene):
    """Over five seeds: the share of receivers whose exact V lies outside their 99 % interval is at
    most 1 % plus three binomial sigmas; the 99th percentile of |V* - exact| is within the
    tolerance; V*'s bias over the penumbra is within the stopping rule's bound; the regions are the exact ones except at border
    receivers (exact V within 1/max_samples of 0 or 1, or a footprint straddling a region's edge)
    and at a few whose exact V is near 0 or 1."""
    scene, si, n, geom, v_true, straddles = analytic_scene
    assert ((v_true > 0) & (v_true < 1)).mean() > 0.2 and (v_true == 0).any() and (v_true == 1).any()
    pen = (v_true > 0) & (v_true < 1)
    tol, conf, n_max = 0.01, 0.99, 4096
    border = straddles | (pen & (np.minimum(v_true, 1 - v_true) < 1 / n_max))
    outside, err_p99, bias = [], [], []
    for seed in range(5):
        ref = area.reference(scene, si, n, geom, 6.0, seed=seed, max_samples=n_max, tolerance=tol, confidence=conf)
        outside.append(np.mean((v_true < ref.low) | (v_true > ref.high)))
        err = ref.v - v_true
        err_p99.append(np.percentile(np.abs(err[pen]), 99))
        bias.append((err[pen].mean(), err[pen].std() / np.sqrt(pen.sum())))
        reg = area.regions(ref.hits, ref.samples)
        # a region call may miss only near 0 or 1 (a receiver stops once its zero-count bound is
        # within the tolerance), and rarely: all of n = 512 samples agree with probability
        # <= (1 - f)^n for a minority fraction f: 0.6 % at f = tol, 2e-7 at 3 tol
        wrong = (reg != _region(v_true)) & ~border
        assert np.all(np.minimum(v_true, 1 - v_true)[wrong] <= 3 * tol) and wrong.sum() <= 0.001 * len(v_true)
        st = ref.stats()
        print(f"seed {seed}: outside {outside[-1]:.4f}, p99 {err_p99[-1]:.4f}, regions u/p/l "
              f"{st['umbra']['receivers']}/{st['penumbra']['receivers']}/{st['lit']['receivers']} (exact "
              f"{(v_true == 0).sum()}/{pen.sum()}/{(v_true == 1).sum()}), rays per receiver "
              f"{st['umbra']['rays_per_receiver']:.0f}/{st['penumbra']['rays_per_receiver']:.0f}/"
              f"{st['lit']['rays_per_receiver']:.0f}, capped {st['capped_above_tolerance']}")
    allowance = (1 - conf) + 3 * np.sqrt(conf * (1 - conf) / (5 * len(v_true)))
    assert np.mean(outside) <= allowance
    assert max(err_p99) <= tol
    # the one stopping rule that can bias V*: all of n = 512 samples agreeing at a minority
    # fraction f, an error of f with probability (1 - f)^n, at most 1 / (e (n + 1)) per receiver
    mean, se = np.mean([b[0] for b in bias]), np.sqrt(np.mean([b[1] ** 2 for b in bias]) / 5)
    assert abs(mean) <= 3 * se + 1 / (np.e * 513)


def test_reference_error_falls_at_least_as_fast_as_one_over_sqrt_samples(analytic_scene):
    scene, si, n, geom, v_true, _ = analytic_scene
    err = {}
    for N in (16, 64, 256):
        ref = area.reference(scene, si, n, geom, 6.0, min_samples=16, max_samples=N, adaptive=False)
        assert (ref.samples == N).all()
        err[N] = np.abs(ref.v - v_true).mean()
    print("mean |V* - analytic| by samples:", {k: round(v, 5) for k, v in err.items()})
    assert err[64] <= err[16] * (16 / 64) ** 0.5
    assert err[256] <= err[16] * (16 / 256) ** 0.5


def test_no_receiver_stops_on_a_few_agreeing_samples(analytic_scene):
    """Lit and umbra receivers stop only once the zero-count bound is within the tolerance
    (512 samples: the first stage total at or above 459), and the penumbra takes most rays."""
    scene, si, n, geom, v_true, _ = analytic_scene
    ref = area.reference(scene, si, n, geom, 6.0, max_samples=4096, tolerance=0.01)
    reg = area.regions(ref.hits, ref.samples)
    assert ref.samples[reg != 1].min() >= intervals.samples_to_certify(0.01, 0.99)
    assert (ref.samples[reg != 1] == 512).all()
    st = ref.stats()
    assert st["penumbra"]["rays"] / st["rays"] > 0.5


def test_sample_maps_are_uniform_by_area(variant):
    """Each shape's map from the square preserves area: mean and spread of the samples
    against the shape's own moments (numpy, float64)."""
    rng = np.random.default_rng(3)
    u, v = (mi.Float(rng.random(200000).astype(np.float32)) for _ in range(2))
    p = dr.zeros(mi.Point3f, 200000) + mi.Point3f(0.0, 0.0, -5.0)
    disk = area_surface.geometry(LightSpec("area", position=(0, 0, 0), direction=(0, 0, 1), shape="disk", size=(2.0,)))
    x, _ = disk.sample(u, v, p)
    r2 = x.x.numpy() ** 2 + x.y.numpy() ** 2
    assert np.mean(r2) == pytest.approx(0.5, abs=0.01)         # uniform disk of radius 1: E[r^2] = 1/2
    rect = area_surface.geometry(LightSpec("area", position=(0, 0, 0), direction=(0, 0, 1), shape="rectangle",
                                   size=(2.0, 1.0)))
    x, _ = rect.sample(u, v, p)
    ext = sorted([np.ptp(x.x.numpy()), np.ptp(x.y.numpy())])
    assert ext == pytest.approx([1.0, 2.0], abs=1e-3)
    sph = area_surface.geometry(LightSpec("area", position=(0, 0, 0), shape="sphere", size=(2.0,)))
    x, _ = sph.sample(u, v, p)
    z = x.z.numpy()
    # the cap seen from distance 5: cos >= 1/5, z uniform on [-1, -1/5] (Archimedes)
    assert z.max() <= -0.2 + 1e-4 and np.mean(z) == pytest.approx(-0.6, abs=0.005)


def test_pcss_penumbra_width_matches_similar_triangles_within_a_texel(variant):
    """A square light above a large occluder parallel to the ground: at receivers under it the
    blocker search finds the occluder's depth and the width is L (d - z_b) / z_b."""
    L, Hl, Ho = 0.5, 3.0, 1.0
    scene = mi.load_dict({"type": "scene", "ground": _quad(0.0, 4.0), "occluder": _quad(Ho, 1.5)})
    light = LightSpec("area", position=(0.0, 0.0, Hl), direction=(0.0, 0.0, -1.0), shape="rectangle", size=(L,))
    q = np.array([[0.0, 0.0], [0.2, -0.1], [-0.3, 0.25], [0.1, 0.3]])
    p = mi.Point3f(mi.Float(q[:, 0]), mi.Float(q[:, 1]), mi.Float(np.zeros(len(q))))
    n = dr.zeros(mi.Vector3f, len(q)) + mi.Vector3f(0, 0, 1)
    bbox = (np.array([-4.0, -4, 0]), np.array([4.0, 4, 1]))
    R = 512
    view = pipeline.make_view(light, R, np.c_[q, np.zeros(len(q))], bbox, "fitted")
    assert view.kind == "perspective"
    view = pipeline.make_view(light, R, np.array([[3.0, 3.0, 0.0], [-3, -3, 0]]), bbox, "fitted")  # a wider field
    smap = pipeline.build_map(scene, view)
    rx = Receiver.make(view, p, n, 8.0)
    spec = pipeline.scheme_spec({"name": "constant", "bias": 0.01})
    z_b, width, found = lookup.pcss_estimate(schemes.get("constant"), lookup.resolve(spec.params, rx), rx, smap)
    assert found.numpy().all()
    # expected, in float64: depths along the light's axis; the texel's world width at the
    # receiver from the map's own geometry (a planar map: 2 tan(half) / R per unit depth, times
    # the depth, times (1 + r^2)^(-1/4) off the axis)
    d = Hl * np.ones(len(q))
    zb = Hl - Ho
    w_world = L * (d - zb) / zb
    r2 = (q ** 2).sum(1) / d ** 2
    texel = 2 * np.tan(np.radians(view.cutoff)) / R * d * (1 + r2) ** -0.25
    assert np.abs(z_b.numpy() - zb).max() < 1e-4
    got = width.numpy() * texel
    print("PCSS width (world):", got, "similar triangles:", w_world, "texel:", texel)
    assert np.all(np.abs(got - w_world) <= texel)


def test_point_light_casts_one_reference_ray_per_receiver(variant):
    """A point-light scene: the reference casts exactly one ray per receiver, as before area
    lights (counted on a scene proxy), and run.json's count is the receivers'."""
    class Counting:
        def __init__(self, scene):
            self.scene, self.rays = scene, 0

        def ray_intersect_preliminary(self, ray, *a, **k):
            self.rays += dr.width(ray.o)
            return self.scene.ray_intersect_preliminary(ray, *a, **k)

        def ray_test(self, ray, *a, **k):
            self.rays += dr.width(ray.o)
            return self.scene.ray_test(ray, *a, **k)

    sd = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane_box"}), (64, 64))
    gb = pipeline.gbuffer(sd)
    light = LightSpec("point", position=(1.0, -1.0, 3.0), direction=(0, 0, -1))
    counting = Counting(sd.scene)
    sd.scene, real = counting, sd.scene
    setup = pipeline.light_setup(sd, gb, light, "p")
    sd.scene = real
    assert counting.rays == len(setup.pixels) == setup.reference_rays > 1000
    assert setup.ref is None


@pytest.mark.slow
def test_point_light_run_counts_receivers_as_reference_rays(run_dict):
    cfg = base_config(camera={"resolution": [64, 64]}, scene=[{"builtin": "plane_box"}],
                      light=[{"type": "point", "position": [1.0, -1.0, 3.0]}], map={"resolution": 64,
                                                                                     "view": "cube"})
    res = run_dict(cfg)
    sd = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane_box"}), (64, 64))
    setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), sd.lights_for(config.parse(cfg).lights)[0], "p")
    assert res.run["rays"]["reference"] == len(setup.pixels)
    assert res.run["reference_regions"] == []


def test_soft_metrics_by_hand():
    # receivers: umbra (0/16), penumbra (8/16), lit (16/16), lit (16/16)
    hits, samples = np.array([0, 8, 16, 16]), np.array([16, 16, 16, 16])
    v = np.array([0.75, 0.25, 1.0, 0.25])
    m = metrics.soft(v, hits, samples, np.array([0.1, 0.2, 0.1, 0.1]), np.array([True, True, True, False]))
    assert (m["n_umbra"], m["n_penumbra"], m["n_lit"]) == (1, 1, 2)
    assert m["mae_umbra"] == 0.75 and m["mae_penumbra"] == 0.25 and m["mae_lit"] == 0.375
    assert m["rmse_lit"] == pytest.approx(np.sqrt(0.75 ** 2 / 2))
    assert m["mean_abs_error"] == pytest.approx((0.75 + 0.25 + 0 + 0.75) / 4)
    assert (m["n_acne"], m["n_peterpan"]) == (1, 1)           # the lit 0.25 and the umbra 0.75; not the penumbra
    assert m["acne_rate"] == 0.5 and m["peterpan_rate"] == 1.0
    assert (m["n_acne_self"], m["n_acne_edge"]) == (0, 1)      # the acne receiver's texel: another surface
    assert m["ref_half_width_max"] == 0.2
    empty = metrics.soft(np.array([0.5]), np.array([3]), np.array([16]), np.array([0.2]), np.ones(1, bool))
    assert np.isnan(empty["mae_umbra"]) and np.isnan(empty["acne_rate"]) and np.isnan(empty["peterpan_rate"])


@pytest.mark.parametrize("light, key", [
    ({"type": "area"}, "light[0].shape"),
    ({"type": "area", "shape": "hexagon"}, "light[0].shape"),
    ({"type": "area", "shape": "rectangle", "position": [0, 0, 3]}, "light[0].size"),
    ({"type": "area", "shape": "disk", "position": [0, 0, 3], "size": -1}, "light[0].size"),
    ({"type": "area", "shape": "emitter", "size": 1}, "light[0].size"),
    ({"type": "area", "shape": "sphere", "position": [0, 0, 3], "size": 1, "min_samples": 64, "max_samples": 32},
     "light[0].max_samples"),
    ({"type": "area", "shape": "disk", "position": [0, 0, 3], "size": 1, "max_samples": 1000}, "light[0].max_samples"),
    ({"type": "area", "shape": "disk", "position": [0, 0, 3], "size": 1, "confidence": 1.0}, "light[0].confidence"),
    ({"type": "area", "shape": "disk", "position": [0, 0, 3], "size": 1, "replicates": 1}, "light[0].replicates"),
])
def test_bad_area_lights_are_refused_naming_the_key(light, key):
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(light=[light]), "x.toml")
    assert e.value.key == key and "x.toml" in str(e.value)


def test_bad_pcf_wide_width_is_refused():
    with pytest.raises(ConfigError, match="pcf_wide:K"):
        config.parse(base_config(map={"filter": "pcf_wide:1"}), "x.toml")


@pytest.mark.slow
def test_area_light_run_end_to_end(run_dict):
    """A rectangle light over plane_box: rows with soft metrics, the V, V*, |V - V*| images,
    run.json's reference rays equal to the regions' sum, and per-tap adaptive bias no worse than
    a constant bias in the lit region under a wide kernel."""
    cfg = base_config(camera={"resolution": [64, 64]}, scene=[{"builtin": "plane_box"}],
                      light=[{"type": "area", "shape": "rectangle", "position": [0.5, 0.3, 3.0], "size": 1.0,
                              "max_samples": 64}],
                      map={"resolution": 128, "filter": ["nearest", "pcf_wide:5", "pcss"]},
                      scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "adaptive_tap"}])
    res = run_dict(cfg, report=True)
    assert len(res.rows) == 6 and all(r["view"] == "perspective" for r in res.rows)
    reg = res.run["reference_regions"][0]
    assert res.run["rays"]["reference"] == reg["rays"] == sum(reg[k]["rays"] for k in area.REGIONS)
    # 64 samples cannot certify 0.01 at 99 % (459 needed): every receiver takes all 64
    assert reg["penumbra"]["rays_per_receiver"] == 64 and reg["umbra"]["rays_per_receiver"] == 64
    assert reg["capped_above_tolerance"] == sum(reg[k]["receivers"] for k in area.REGIONS)
    for r in res.rows:
        assert r["n_umbra"] + r["n_penumbra"] + r["n_lit"] == r["n_receivers"]
        assert r["n_penumbra"] > 0 and r["n_umbra"] > 0
        for name in ("v", "vstar", "abserr"):
            assert (res.out / "images" / "plane_box_0_area" / f"{r['case']}_{name}.png").is_file()
    assert (res.out / "plots" / "soft_plane_box_0_area.png").is_file()
    assert "## Soft shadows (area lights)" in (res.out / "table.md").read_text()
    wide = {r["scheme"]: r for r in res.rows if r["filter"] == "pcf_wide:5"}
    assert wide["adaptive_tap"]["mae_lit"] <= wide["constant"]["mae_lit"] + 1e-9


def test_cornell_box_luminaire_is_the_light_and_its_map_steps_over_it(variant):
    spec = pipeline.scene_spec({"file": str(MESHES / "cbox_mitsuba" / "cbox.xml")})
    sd = pipeline.load_scene(spec, (48, 48))
    lights = sd.lights_for([LightSpec("area", shape="emitter", max_samples=32)])
    assert len(lights) == 1
    lum = lights[0]
    i = lum.emitter_shapes[0]
    assert sd.scene.shapes()[i].is_emitter()
    assert np.allclose(lum.direction, (0, -1, 0)) and lum.size[0] == pytest.approx(np.sqrt(130 * 105), rel=1e-4)
    gb = pipeline.gbuffer(sd)
    setup = pipeline.light_setup(sd, gb, lum, "0:area")
    assert i not in set(setup.shape.tolist())          # the luminaire is no receiver of itself
    view = pipeline.make_view(lum, 64, pipeline.points_np(setup.p), sd.bbox, "fitted")
    smap = pipeline.build_map(sd.scene, view)
    shapes = set(smap.shape.numpy().tolist())
    assert i not in shapes and len(shapes - {0xFFFFFFFF}) >= 4


def test_plugins_with_area_emitters(variant):
    """dsm_shadow with area = true: its dsm.Vstar AOV (one random area sample per camera sample)
    averages to the stratified reference's V* over the image; dsm_error renders |V - V*| whose
    pixels are black exactly outside the receivers."""
    import dsm_plugins
    dsm_plugins.register()
    scene = mi.load_file(str(MESHES / "cbox_mitsuba" / "cbox.xml"), res=48)
    shadow = mi.load_dict({"type": "dsm_shadow", "area": True, "filter": "pcss", "scheme": "adaptive_tap",
                           "resolution": 256, "aovs": True, "samples": 64})
    img = np.array(mi.render(scene, integrator=shadow, spp=32))
    sd = pipeline.scene_from_mitsuba(scene)
    lum = pipeline.area_emitter_lights(scene, LightSpec("area", shape="emitter", min_samples=256, max_samples=256,
                                                        tolerance=0.0))[0]
    setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), lum, "0:area")
    vstar = np.zeros(48 * 48)
    vstar[setup.pixels] = setup.v_frac
    assert img.shape == (48, 48, 5)
    print("mean V* AOV", img[..., 4].mean(), "reference", vstar.mean(), "mean V", img[..., 3].mean())
    assert img[..., 4].mean() == pytest.approx(vstar.mean(), abs=0.02)
    assert img[..., 3].mean() == pytest.approx(vstar.mean(), abs=0.1)        # the map's V: close, not equal
    err = np.array(mi.render(scene, integrator=mi.load_dict({"type": "dsm_error", "area": True, "filter": "pcss",
                                                              "resolution": 256, "samples": 32})))
    outside = np.ones(48 * 48, bool)
    outside[setup.pixels] = False
    assert np.all(err.reshape(-1, 3)[outside] == 0)
    assert (err.reshape(-1, 3)[~outside].sum(1) > 0).mean() > 0.99            # magma's darkest is not black


def test_adaptive_tap_clamps_the_plane_depth_by_the_taps_offset(variant):
    """The per-tap plane depth is kept within max_slope x the tap's lateral distance (texels x
    texel width, at least one texel) of the receiver's depth (numpy, float64)."""
    from types import SimpleNamespace
    from dsm.schemes import adaptive_tap
    rng = np.random.default_rng(5)
    n = 2000
    d, z1 = rng.uniform(2, 3, n), rng.uniform(1, 3, n)
    plane = d + rng.normal(0, 0.5, n)
    du, dv, tw = rng.uniform(-4, 4, n), rng.uniform(-4, 4, n), rng.uniform(0.005, 0.02, n)
    f = lambda a: mi.Float(np.asarray(a, np.float32))
    rx = SimpleNamespace(depth=f(d), u_map=f(np.full(n, 10.0)), v_map=f(np.full(n, 10.0)), texel_world=f(tw),
                         scene_scale=mi.Float(5.0))
    tap = SimpleNamespace(z1=f(z1), cu_map=f(10.0 + du), cv_map=f(10.0 + dv), receiver_plane_depth=lambda r: f(plane))
    p = SimpleNamespace(K=mi.Float(1e-4), max_slope=mi.Float(8.0))
    got = adaptive_tap.margin(rx, tap, p).numpy()
    reach = 8.0 * np.maximum(np.hypot(du, dv), 1.0) * tw
    want = z1 + 1e-4 * 5.0 - np.clip(plane, d - reach, d + reach)
    assert (np.abs(plane - d) > reach).mean() > 0.5           # the clamp acts on most of these taps
    np.testing.assert_allclose(got, want, atol=2e-6)


@pytest.mark.slow
def test_an_area_reference_in_chunks_is_the_reference_in_one_launch(monkeypatch):
    """A stage launched every receiver's samples at once: max_samples = 2^20 over a few thousand
    receivers passed 2^32 lanes (Dr.Jit's UInt32 index) and the memory. Now receivers go in
    chunks of at most STAGE_LANES rays; each receiver's samples have their own seeds, so V* is
    the same: here with chunks of one to a few receivers against one launch per stage."""
    import numpy as np
    from dsm.truth import area
    from dsm.config import read as config
    from dsm import pipeline
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [24, 24]},
                      light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5,
                              "max_samples": 512, "tolerance": 0.05}])
    sd = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane_box"}), (24, 24))
    light = sd.lights_for(config.parse(cfg).lights)[0]
    gb = pipeline.gbuffer(sd)
    monkeypatch.setattr(area, "STAGE_LANES", 1 << 30)
    whole = pipeline.light_setup(sd, gb, light, "a").ref
    monkeypatch.setattr(area, "STAGE_LANES", 40)
    chunked = pipeline.light_setup(sd, gb, light, "a").ref
    assert len(whole.hits) > 100 and len(np.unique(whole.samples)) >= 3    # receivers stopped at several stages
    assert np.array_equal(whole.hits, chunked.hits) and np.array_equal(whole.samples, chunked.samples)
    assert np.array_equal(whole.low, chunked.low) and np.array_equal(whole.high, chunked.high)
