"""PCF filters (seed 000, section 5) and stored depth formats (seed 002, depth-buffer precision)."""
import numpy as np
import pytest

from conftest import base_config


def _edge_setup(R=60):
    """An open plate 0.2 above the ground, light straight down: the plate's edge x = 0.75 is a
    straight shadow edge along the map's v axis (the view's ex is +x)."""
    import drjit as dr
    import mitsuba as mi
    from dsm import config, gbuffer, reference, scenes, shadowmap
    from dsm.config import LightSpec
    from dsm.views import OrthographicView
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
    import mitsuba as mi
    from dsm import schemes
    from dsm.lookup import Receiver, visibility
    sd, view, smap, p, n, vstar = _edge_setup()
    rx = Receiver.make(view, p, n, sd.diagonal)
    const = schemes.get("constant")
    prm = const.Params(bias=__import__("dsm").config.Length(0.05, "world"))
    v_bil = visibility(const, prm, rx, smap, "pcf_bilinear")[0].numpy()
    v_near = visibility(const, prm, rx, smap, "nearest")[0].numpy()
    u = rx.u.numpy()
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
    # texels (e: the edge's offset in its texel), bilinear's ramp costs 1/4 + (e - c)^2 (c: the
    # boundary midway between the two centres), never less than nearest. Here e = 0.25, c = 0:
    # 0.25 against 0.3125 texel, a ratio of 1.25.
    assert abs(u_edge - np.floor(u_edge) - 0.25) < 1e-3
    mae_bil, mae_near = np.abs(v_bil - vstar).mean(), np.abs(v_near - vstar).mean()
    assert 1.1 < mae_bil / mae_near < 1.4, (mae_bil, mae_near)


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
    for f in ("pcf_bilinear", "pcf_jitter4x4"):
        mae = res.where(filter=f).mean_abs_error
        assert np.all(np.isfinite(mae))
    # PCF gives fractional visibility: its mean |V - V*| differs from its error rate somewhere
    r = res.where(filter="pcf_jitter4x4", scheme="none")
    assert np.any(np.abs(r.mean_abs_error - r.error_rate) > 1e-3)


def _deep_scene_rows(run_dict, fmt_list):
    """plane_box lit at 45 degrees by a spot 1e4 units away: a depth range of 1e4 over a scene 8
    units wide, the ground's depth spanning many unorm16 steps."""
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [128, 128]},
                      light=[{"type": "spot", "position": [7071.0, -100.0, 7071.0], "target": [0.0, 0.0, 0.0],
                              "cutoff": 0.04}],
                      map={"resolution": 256, "format": fmt_list},
                      scheme=[{"name": "constant", "bias": 0.05}])
    return run_dict(cfg)


def test_unorm16_on_a_deep_scene_makes_acne_that_float32_does_not(run_dict):
    res = _deep_scene_rows(run_dict, ["float32", "unorm16", "unorm24"])
    rate = {r["format"]: r["acne_rate"] for r in res.rows}
    assert rate["float32"] < 0.002
    assert rate["unorm24"] < 0.002           # 1e4 / 2^24 = 6e-4 per step: below the bias
    assert rate["unorm16"] > 0.05            # 1e4 / 2^16 = 0.15 per step: rounding beats the 0.05 bias


def test_ndc24_error_grows_with_distance_as_its_spacing_predicts(variant):
    from dsm import formats
    from dsm.views import PerspectiveView
    bbox = (np.array([-1.0, -1, 0]), np.array([1.0, 1, 1000]))
    view = PerspectiveView((0, 0, 1001.0), (0, 0, -1), 10, bbox, 16)
    z = np.geomspace(2.0, 900.0, 4000)
    z = z * (1 + 1e-3 * np.sin(np.arange(z.size)))       # off-grid depths
    err = np.abs(formats.quantize_np(z, view, "ndc24") - z)
    step = formats.world_step(view, "ndc24", z)
    assert np.all(err <= 0.5 * step * 1.01 + 1e-9)        # within half a step everywhere
    bins = np.array_split(np.arange(z.size), 8)
    mean_err = np.array([err[b].mean() for b in bins])
    assert np.all(np.diff(mean_err) > 0)                   # grows with distance from the light
    ratio = mean_err[-1] / mean_err[0]
    pred = (step[bins[-1]].mean()) / (step[bins[0]].mean())
    assert 0.5 * pred < ratio < 2.0 * pred                 # as z^2 predicts
    uerr = np.abs(formats.quantize_np(z, view, "unorm24") - z)
    assert abs(uerr[bins[-1]].mean() / uerr[bins[0]].mean() - 1) < 0.3   # unorm's error does not grow


def test_a_bias_sweep_of_8_values_compiles_the_lookup_kernel_once(run_dict):
    biases = [f"{k} texel" for k in (0.1, 0.2, 0.3, 0.5, 0.8, 1.3, 2.1, 3.4)]
    cfg = base_config(scheme=[{"name": "constant", "bias": biases}], map={"resolution": 64},
                      camera={"resolution": [64, 64]})
    res = run_dict(cfg)
    compiled = res.lookup_kernels_compiled
    assert len(compiled) == 8
    assert np.all(compiled[1:] == 0), compiled      # values 2..8 reuse the first one's kernels
    assert len(set(np.round(res.acne_rate, 6))) > 3  # and the values really differ
