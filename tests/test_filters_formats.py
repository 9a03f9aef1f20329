"""PCF filters (Weiskopf & Ertl 2003, section 5) and stored depth formats (Microsoft's Common Techniques article, depth-buffer precision)."""
import numpy as np
import pytest

from conftest import base_config


def _edge_setup(R=60):
    """An open plate 0.2 above the ground, light straight down: the plate's edge x = 0.75 is a
    straight shadow edge along the map's v axis (the view's ex is +x)."""
    import drjit as dr
    import mitsuba as mi
    from dsm.config import read as config
    from dsm.scenes import gbuffer, load as scenes
    from dsm.truth import reference
    from dsm.maps import shadowmap
    from dsm.config.read import LightSpec
    from dsm.maps.views import OrthographicView
    cfg = config.parse(base_config(scene=[{"builtin": "floating_plate"}]), "<test>")
    sd = scenes.load(cfg.scenes[0], (256, 256))
    gb = gbuffer.cast(sd.scene, sd.sensor, 256, 256)
    ground = sd.shape_names.index("ground")
    pts = gb.p
    xs, ys = (c.numpy() for c in (pts.x, pts.y))
    sel = np.flatnonzero(gb.hit & (gb.shape.numpy() == ground) & (np.abs(ys) < 0.5) & (np.abs(xs - 0.75) < 0.3))
    idx = mi.UInt32(sel.astype(np.uint32))
    p, n = dr.gather(mi.Point3f, gb.p, idx), dr.gather(mi.Vector3f, gb.n, idx)
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    light = LightSpec("directional", direction=(0.0, 0.0, -1.0))
    view = OrthographicView((0, 0, -1), np.array([[-2.0, -2, 0], [2, 2, 0]]), sd.bbox, R)
    smap = shadowmap.build(sd.scene, view, set())
    vstar, _ = reference.visibility(sd.scene, si, light, reference.scene_magnitude(sd.bbox))
    return sd, view, smap, p, n, vstar.numpy().astype(bool)


def test_bilinear_pcf_rises_linearly_across_one_texel(variant):
    from dsm import schemes
    from dsm.maps.lookup import visibility
    from dsm.maps.receiver import Receiver
    sd, view, smap, p, n, vstar = _edge_setup()
    rx = Receiver.make(view, p, n, sd.diagonal)
    const = schemes.get("constant")
    prm = const.Params(bias=__import__("dsm").Length(0.05, "world"))
    v_bil = visibility(const, prm, rx, smap, "pcf_bilinear")[0].numpy()
    v_near = visibility(const, prm, rx, smap, "nearest")[0].numpy()
    u = rx.u_map.numpy()
    # the analytic answer: texel k is lit iff its centre ray misses the plate (centre x > 0.75)
    L = view.extent
    x0 = float(view.origin_np @ view.axes_np[0])
    u_edge = (0.75 - x0) / L * view.resolution
    lit = lambda k: ((k + 0.5) > u_edge).astype(float)
    x = u - 0.5
    i0 = np.floor(x)
    f = x - i0
    expected = (1 - f) * lit(i0) + f * lit(i0 + 1)
    np.testing.assert_allclose(v_bil, expected, atol=1e-4)
    ramp = (expected > 0.02) & (expected < 0.98)
    assert ramp.sum() > 20 and np.ptp(u[ramp]) <= 2.0    # the ramp is one texel wide (centre to centre)
    np.testing.assert_array_equal(v_near, lit(np.floor(u)))
    # Against the exact (hard) edge, per unit length of edge: nearest is wrong over min(e, 1 - e)
    # texels (e: the edge's offset in its texel); bilinear's ramp between the centres on either
    # side of the edge costs x^2 / 2 + (1 - x)^2 / 2 = 1/4 + (x - 1/2)^2 texels (x: the edge's
    # offset from the last shadowed centre, (e + 1/2) mod 1), never less than nearest.
    e = u_edge - np.floor(u_edge)
    assert 0.1 < e < 0.9, e                       # not at a texel boundary, where nearest costs nothing
    x = (e + 0.5) % 1.0
    predicted = (0.25 + (x - 0.5) ** 2) / min(e, 1 - e)
    mae_bil, mae_near = np.abs(v_bil - vstar).mean(), np.abs(v_near - vstar).mean()
    assert mae_bil / mae_near == pytest.approx(predicted, rel=0.1), (mae_bil, mae_near, e, predicted)


@pytest.mark.slow
def test_every_filter_runs_with_every_scheme_and_view(run_dict):
    from dsm.schemes import REGISTRY
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                      light=[{"type": "scene"}, {"type": "point", "position": [1, -1, 3]}],
                      map={"resolution": 32, "filter": ["nearest", "pcf_bilinear", "pcf_jitter4x4"],
                           "view": ["paraboloid", "dual_paraboloid", "cube"]},
                      scheme=[{"name": s.NAME} for s in REGISTRY])
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0, [s for s in res.run["status"] if s["status"] == "failed"][:2]
    assert len(res) == len(REGISTRY) * 3 * 4
    # every receiver in error is off by at least 1/2, so error_rate / 2 <= mean |V - V*| <= 1,
    # with equality to error_rate for nearest lookup (V is 0 or 1)
    rows = [r for r in res.rows if r["n_receivers"] > 0]
    assert len(rows) > 0.9 * len(res)
    for r in rows:
        if r["filter"] == "nearest":
            assert r["mean_abs_error"] == pytest.approx(r["error_rate"], abs=1e-12), r["case"]
        else:
            assert 0.5 * r["error_rate"] - 1e-12 <= r["mean_abs_error"] <= 1.0, r["case"]
    # PCF gives fractional visibility: its mean |V - V*| differs from its error rate somewhere
    r = res.where(filter="pcf_jitter4x4", scheme="none")
    assert np.any(np.abs(r.mean_abs_error - r.error_rate) > 1e-3)


SPOT = {"type": "spot", "position": [7071.0, -100.0, 7071.0], "target": [0.0, 0.0, 0.0], "cutoff": 0.04}
PLANE_BOX_BBOX = (np.array([-4.0, -4.0, 0.0]), np.array([4.0, 4.0, 1.0]))   # the 8 x 8 ground, the unit box on it


def unorm_step(view, bits):
    """A unorm format's world step, from its definition: [near, far] in 2^b - 1 steps."""
    return (view.far - view.near) / (2.0 ** bits - 1.0)


def ndc24_step(z, n, f):
    """ndc24's world step at depth z, from its definition ndc = f / (f - n) (1 - n / z) in 24 bits:
    d ndc / dz = f n / ((f - n) z^2), so one step of 1 / (2^24 - 1) is z^2 (f - n) / (f n (2^24 - 1))."""
    return np.asarray(z, np.float64) ** 2 * (f - n) / (f * n * (2.0 ** 24 - 1.0))


@pytest.mark.slow
def test_stored_formats_on_a_deep_scene_make_the_acne_their_step_predicts(run_dict):
    """plane_box lit at 45 degrees by a spot 1e4 units away: a depth range of 1e4 over a scene 8
    units wide. The rounding error e of a stored depth is uniform over one step s, so with a
    constant bias b (and a receiver's own depth spread within its texel, here at most
    tan(45) * texel * sqrt(1/2) = 0.039, never reaching s / 2 - b) a lit receiver is acne when
    e > b: a rate of 1/2 - b / s where s / 2 > b, none where s / 2 + 0.039 < b."""
    from dsm.maps.views import PerspectiveView
    bias = 0.05
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [128, 128]}, light=[SPOT],
                      map={"resolution": 256, "format": ["float32", "unorm16", "unorm24", "ndc24"]},
                      scheme=[{"name": "constant", "bias": bias}])
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    rate = {r["format"]: r["acne_rate"] for r in res.rows}
    # the spot's view, as the runner makes it: its [near, far] gives the steps
    view = PerspectiveView(SPOT["position"], np.subtract(SPOT["target"], SPOT["position"]), SPOT["cutoff"],
                           PLANE_BOX_BBOX, 256)
    s16, s24 = unorm_step(view, 16), unorm_step(view, 24)
    assert s16 / 2 > bias and s24 / 2 + 0.039 < bias                      # 0.154 and 6e-4 per step
    # ndc24's n: the light's distance to the scene's bounds, at least far / 1000 (formats' definition)
    corners = np.array([[x, y, z] for x in (-4.0, 4.0) for y in (-4.0, 4.0) for z in (0.0, 1.0)])
    axis = np.subtract(SPOT["target"], SPOT["position"]) / np.linalg.norm(np.subtract(SPOT["target"], SPOT["position"]))
    n = max(float(np.min((corners - SPOT["position"]) @ axis)), view.far * 1e-3)
    assert ndc24_step(view.far, n, view.far) / 2 + 0.039 < bias
    assert rate["unorm16"] == pytest.approx(0.5 - bias / s16, abs=0.02), (rate, s16)
    for fmt in ("float32", "unorm24", "ndc24"):
        assert rate[fmt] < 0.002, (fmt, rate)


def test_quantization_error_is_the_format_step_rounded_to_nearest(variant):
    """Stored depths read back within half a step of the original, and, rounding to nearest,
    off by a quarter step on average (uniform over the half step). The steps come from each
    format's definition with the view's near and far: ndc24's grows as z^2 (fine near the
    light, coarse far from it), unorm's is constant."""
    from dsm.maps import formats
    from dsm.maps.views import PerspectiveView
    bbox = (np.array([-1.0, -1, 0]), np.array([1.0, 1, 1000]))
    view = PerspectiveView((0, 0, 1001.0), (0, 0, -1), 10, bbox, 16)
    # ndc24's n: the light's distance to the scene's bounds (1001 - 1000), at least far / 1000
    n, f = max(1.0, view.far * 1e-3), view.far
    z = np.geomspace(2.0, 900.0, 4000)
    z = z * (1 + 1e-3 * np.sin(np.arange(z.size)))       # off-grid depths
    bins = np.array_split(np.arange(z.size), 8)
    for fmt, step in (("ndc24", ndc24_step(z, n, f)), ("unorm24", np.full(z.size, unorm_step(view, 24))),
                      ("unorm16", np.full(z.size, unorm_step(view, 16)))):
        err = np.abs(formats.quantize_np(z, view, fmt) - z)
        assert np.all(err <= 0.5 * step * (1 + 1e-3)), fmt          # within half a step everywhere
        for b in bins:
            assert np.mean(err[b] / step[b]) == pytest.approx(0.25, abs=0.03), (fmt, z[b[0]])
    mean_err = np.array([np.abs(formats.quantize_np(z[b], view, "ndc24") - z[b]).mean() for b in bins])
    assert np.all(np.diff(mean_err) > 0)                  # ndc24's error grows with distance from the light
    step = ndc24_step(z, n, f)
    pred = step[bins[-1]].mean() / step[bins[0]].mean()  # as z^2: about 4e4 from the first bin to the last
    assert mean_err[-1] / mean_err[0] == pytest.approx(pred, rel=0.25)


def test_a_bias_sweep_of_8_values_compiles_the_lookup_kernel_once(run_dict):
    biases = [f"{k} texel" for k in (0.1, 0.2, 0.3, 0.5, 0.8, 1.3, 2.1, 3.4)]
    cfg = base_config(scheme=[{"name": "constant", "bias": biases}], map={"resolution": 64},
                      camera={"resolution": [64, 64]})
    res = run_dict(cfg)
    compiled = res.lookup_kernels_compiled
    assert len(compiled) == 8
    assert np.all(compiled[1:] == 0), compiled      # values 2..8 reuse the first one's kernels
    assert len(set(np.round(res.acne_rate, 6))) > 3  # and the values really differ
