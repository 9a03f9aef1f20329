"""Hybrid lookups (dsm.hybrid) against known answers: every receiver traced is the reference bit for
bit on every built-in scene; the oracle traces exactly the map's wrong receivers; the classifier's
flags and tile cut-off; the band never adds error and its ray fraction on a plane at a known slope
is the one derived here; the config's [hybrid] is read, swept and refused in one line."""
import math

import numpy as np
import pytest

from conftest import base_config

SPOT = dict(type="spot", position=(-1.5, 2.0, 3.0), target=(0.0, 0.0, 0.0), cutoff=40.0)


def _context(builtin="plane_box", light=None, params=None, res=48, R=64, camera=None):
    """A MapContext of one built-in scene (its own first light, or ``light``; ``camera``: a CameraSpec
    or the scene's own) and an exact side for rays."""
    import dsm.pipeline as pl
    from dsm.case import MapContext, Where
    sd = pl.load_scene(pl.scene_spec({"builtin": builtin, **(params or {})}), (res, res), camera)
    gb = pl.gbuffer(sd)
    spec = pl.LightSpec(**light) if light else sd.lights_for((pl.LightSpec("scene", label="scene"),))[0]
    setup = pl.light_setup(sd, gb, spec, "l")
    view = pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox, "cube" if spec.type == "point" else None)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool)) if pl.is_positional(setup.light) else setup
    smap = pl.build_map(sd.scene, view, ())
    stored = {"float32": pl.store(smap, "float32")}
    rx = {"float32": pl.receivers(stored["float32"].view, setup, sd.diagonal)}
    where = Where(sd.label, "l", view.kind, R, view.n_texels, "none")
    return MapContext(where, sd, gb, setup, view, smap, stored, rx, 7, 1)


def _hybrid(rule, origin="spawn", **params):
    from dsm.core.types import HybridSpec
    from dsm.hybrid import get
    return HybridSpec(rule, get(rule).Params(**params), origin)


def _measure(ctx, hybrid, scheme=None):
    """(hybrid columns, V after the rays, the map's V, the rule's Selection) of one case of ``ctx``."""
    import dsm.pipeline as pl
    from dsm.case import Case, evaluate
    from dsm.case.evaluation import hybrid_parts
    from dsm.hybrid import get, trace
    case = Case("0001", pl.scheme_spec(scheme or {"name": "constant", "bias": "0.5 texel"}), "nearest", "float32",
                hybrid)
    res = evaluate(ctx, case)
    inputs, exact = hybrid_parts(ctx, case, res.v)
    cols, v_after = trace.measure(hybrid, inputs, exact, 1)
    sel = get(hybrid.rule).select(inputs, hybrid.params)
    assert {k: cols[k] for k in ("hybrid_rays", "hybrid_n_acne", "hybrid_n_peterpan")} == \
        {k: res.measured[k] for k in ("hybrid_rays", "hybrid_n_acne", "hybrid_n_peterpan")}
    return res.measured, v_after, np.asarray(res.v), sel


def _builtin_cases():
    from dsm.scenes.params import BUILTINS
    return [(b, None) for b in BUILTINS] + [("plane_box", SPOT)]


@pytest.mark.slow
@pytest.mark.parametrize("builtin,light", _builtin_cases(), ids=lambda x: x if isinstance(x, str) else "spot")
def test_every_receiver_traced_is_the_reference_bit_for_bit(builtin, light):
    """Rule ``all`` with the kit's spawn rule and whole rays: V after the rays is V*, receiver by receiver."""
    ctx = _context(builtin, light)
    cols, v_after, _, _ = _measure(ctx, _hybrid("all"))
    n = len(ctx.setup.pixels)
    assert n > 0
    assert cols["hybrid_rays"] == n and cols["ray_fraction"] == 1.0
    assert np.array_equal(v_after >= 0.5, ctx.setup.v_star)
    assert cols["hybrid_error_rate"] == 0.0 and cols["hybrid_n_ray_wrong"] == 0 and cols["hybrid_shortened"] == 0


def test_shortened_rays_report_the_error_they_add():
    """The classifier's ray interval: the rays' own wrong answers are counted (whole rays: none)."""
    ctx = _context("floating_plate")
    kw = dict(bRejectLitPixels=False, tileCutOff=0)
    whole, _, _, _ = _measure(ctx, _hybrid("classifier", bUseCascadesForRayT=False, **kw))
    short, _, _, sel = _measure(ctx, _hybrid("classifier", bUseCascadesForRayT=True, **kw))
    assert whole["hybrid_n_ray_wrong"] == 0 and whole["hybrid_shortened"] == 0
    assert short["hybrid_shortened"] == 1 and sel.t_min is not None
    assert short["hybrid_rays"] == whole["hybrid_rays"]
    # what the shortening adds is exactly the rays it got wrong
    added = short["hybrid_n_acne"] + short["hybrid_n_peterpan"] - whole["hybrid_n_acne"] - whole["hybrid_n_peterpan"]
    assert added == short["hybrid_n_ray_wrong"]


@pytest.mark.parametrize("scheme", [{"name": "none"}, {"name": "constant", "bias": "2 texel"}])
def test_the_oracle_traces_exactly_the_wrong_receivers_and_leaves_no_error(scheme):
    ctx = _context("plane_box")
    cols, v_after, v_map, sel = _measure(ctx, _hybrid("oracle"), scheme)
    wrong = (v_map >= 0.5) != ctx.setup.v_star
    assert np.array_equal(sel.trace, wrong)
    assert cols["hybrid_rays"] == wrong.sum() == cols["n_acne"] + cols["n_peterpan"]
    assert cols["hybrid_error_rate"] == 0.0 and np.array_equal(v_after >= 0.5, ctx.setup.v_star)


def test_the_oracles_budget_is_the_floor_of_the_curve():
    ctx = _context("plane_box")
    full, _, _, _ = _measure(ctx, _hybrid("oracle"), {"name": "none"})
    half, _, _, _ = _measure(ctx, _hybrid("oracle", budget=0.1), {"name": "none"})
    n = full["n_receivers"]
    assert half["hybrid_rays"] == min(math.floor(0.1 * n), full["hybrid_rays"])
    assert half["hybrid_n_acne"] + half["hybrid_n_peterpan"] == full["hybrid_rays"] - half["hybrid_rays"]


def test_classifier_without_a_sun_or_rejection_traces_every_flagged_pixel():
    from dsm.hybrid import classifier
    ctx = _context("l_shape")
    hyb = _hybrid("classifier", sunSizeLightSpace=0.0, bRejectLitPixels=False)
    _, _, _, sel = _measure(ctx, hyb)
    flag, lit, _, _ = classifier.search(ctx.receivers["float32"], ctx.stored["float32"], hyb.params)
    flag = flag.numpy().astype(bool)
    assert not lit.numpy().any()             # nothing rejected as lit
    assert flag.any() and np.array_equal(sel.trace, flag)


def test_classifier_cut_off_zero_never_traces_fewer_rays():
    ctx = _context("plane_box", SPOT)
    amd = _measure(ctx, _hybrid("classifier"))[3].trace        # the sample's default: tileCutOff 0
    for cut in (4, 16, 32):
        fewer = _measure(ctx, _hybrid("classifier", tileCutOff=cut))[3].trace
        assert not (fewer & ~amd).any() and amd.sum() >= fewer.sum()
    assert _measure(ctx, _hybrid("classifier", tileCutOff=32))[3].trace.sum() == 0   # 32 pixels a tile at most


def test_classifier_tiles_are_eight_by_four():
    from dsm.hybrid.classifier import tiles
    px = np.array([0, 7, 8, 3 * 20, 4 * 20, 4 * 20 + 19])
    assert tiles(px, 20).tolist() == [0, 0, 1, 0, 3, 5]


@pytest.mark.parametrize("builtin", ["plane_box", "l_shape", "floating_plate"])
def test_band_never_adds_error_and_more_rays_never_add_error(builtin):
    ctx = _context(builtin)
    errors, rays = [], []
    for k in (0.0, 0.05, 0.25, 1.0, 4.0, 64.0):
        cols, _, _, _ = _measure(ctx, _hybrid("band", k=k), {"name": "none"})
        errors.append(cols["hybrid_n_acne"] + cols["hybrid_n_peterpan"])
        rays.append(cols["hybrid_rays"])
        assert errors[-1] <= cols["n_acne"] + cols["n_peterpan"]
    assert rays[0] == 0 and rays == sorted(rays)
    assert errors == sorted(errors, reverse=True)


@pytest.mark.parametrize("tilt", [30.0, 60.0])
def test_band_fraction_on_a_plane_is_the_derived_one(tilt):
    """On a plane tilted ``tilt`` degrees to a light from straight above, depth along the light grows
    by tan(tilt) texels of depth per texel along the plane's downhill direction in the map, and not
    at all across it; a receiver's nearest texel holds the plane's depth at the texel's centre, so
    its gap is |(offset from the centre) . downhill| tan(tilt) texels."""
    import dsm.pipeline as pl
    from dsm.core.types import CameraSpec
    # the camera sees the plane's middle only: every receiver's nearest texel centre is on the plane
    close = CameraSpec(position=(0.0, -1.0, 4.0), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov=20.0)
    ctx = _context("plane", params={"tilt": tilt, "azimuth": 0.0}, res=96, R=48, camera=close)
    rx = ctx.receivers["float32"]
    u, v = (np.asarray(a.numpy(), np.float64) for a in (rx.u_map, rx.v_map))
    off = np.stack([u - np.floor(u) - 0.5, v - np.floor(v) - 0.5], 1)
    # the downhill direction in the map: where a step down the plane's slope lands
    t = math.radians(tilt)
    p0 = np.array([[0.0, 0.0, 0.0]])
    down = np.array([[0.0, math.cos(t), -math.sin(t)]])        # azimuth 0: the tilt axis is x
    pts = pl.mi.Point3f(*(pl.mi.Float(np.concatenate([p0, p0 + 0.01 * down])[:, k]) for k in range(3)))
    pu, pv, _ = ctx.view.project(pts)
    step = np.array([pu.numpy()[1] - pu.numpy()[0], pv.numpy()[1] - pv.numpy()[0]], np.float64)
    gap = np.abs(off @ (step / np.linalg.norm(step))) * math.tan(t)
    for k in (0.05, 0.1, 0.2):
        cols, _, _, _ = _measure(ctx, _hybrid("band", k=k))
        assert cols["hybrid_rays"] == int(np.count_nonzero(gap < k)), k
        assert cols["ray_fraction"] == pytest.approx(np.mean(gap < k), abs=0)
    assert 0.0 < np.mean(gap < 0.1) < 1.0


def test_origin_rules_agree_at_unit_scale():
    ctx = _context("plane_box")
    for origin in ("mitsuba", "wachter_binder", "epsilon"):
        cols, _, _, _ = _measure(ctx, _hybrid("all", origin=origin))
        assert cols["hybrid_n_ray_wrong"] <= 0.002 * cols["n_receivers"], origin


def test_wachter_binder_moves_by_ulps_and_by_a_float_near_zero():
    import drjit as dr
    import mitsuba as mi
    from dsm.hybrid.origins import wachter_binder
    p = mi.Point3f(mi.Float([1000.0, 0.001]), mi.Float([-2.0, 0.0]), mi.Float([0.5, -0.01]))
    n = mi.Vector3f(mi.Float([1.0, 0.0]), mi.Float([-1.0, 0.0]), mi.Float([0.0, 1.0]))
    q = np.array([c.numpy() for c in wachter_binder(p, n)])
    ulps = lambda x, k: (np.array([x], np.float32).view(np.int32) + k).view(np.float32)[0]
    assert q[0, 0] == ulps(1000.0, 256)                       # 256 ulps along n_x = 1
    assert q[1, 0] == ulps(-2.0, 256)                         # n_y = -1 at p_y < 0: away from zero
    assert q[2, 0] == np.float32(0.5)                         # n_z = 0: kept
    assert q[0, 1] == np.float32(0.001) and q[2, 1] == np.float32(-0.01) + np.float32(1 / 65536)   # near 0: a float


def test_config_reads_and_sweeps_hybrid_and_refuses_in_one_line():
    from dsm.config import read
    cfg = read.parse(base_config(hybrid=[{"rule": "band", "k": [0.5, 2.0]},
                                         {"rule": "classifier", "origin": ["spawn", "epsilon"]}]), "<h>")
    assert [(h.rule, h.origin) for h in cfg.hybrid] == [("band", "spawn")] * 2 + [("classifier", "spawn"),
                                                                                 ("classifier", "epsilon")]
    assert read.parse(base_config(hybrid={"rule": "oracle"}), "<h>").hybrid[0].params.budget == 1.0
    bad = [({"rule": "bands"}, "hybrid.rule.*valid.*band"), ({"rule": "band", "kk": 1}, "hybrid.kk"),
           ({"rule": "band", "origin": "offset"}, "hybrid.origin"), ({"k": 1}, "hybrid.rule"),
           ({"rule": "classifier", "tileCutOff": 33}, "hybrid.tileCutOff"),
           ({"rule": "oracle", "budget": 1.5}, "hybrid.budget"),
           ({"rule": "classifier", "bRejectLitPixels": 1}, "hybrid.bRejectLitPixels")]
    for table, match in bad:
        with pytest.raises(read.ConfigError, match=match) as e:
            read.parse(base_config(hybrid=table), "<h>")
        assert "\n" not in str(e.value) and "<h>" in str(e.value)


@pytest.mark.slow
def test_a_run_with_hybrid_writes_its_columns_and_section(run_dict, tmp_path):
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [40, 40]}, map={"resolution": 64},
                      scheme=[{"name": "constant", "bias": "1 texel"}],
                      hybrid=[{"rule": "band", "k": [0.5, 2.0]}, {"rule": "oracle"}])
    res = run_dict(cfg, "hybrid", report=True)
    rows = res.rows
    assert len(rows) == 3 and res.run["n_failed"] == 0
    assert sorted(r["hybrid_rule"] for r in rows) == ["band", "band", "oracle"]
    assert all(r["hybrid_error_rate"] <= r["error_rate"] for r in rows)
    out = tmp_path / "hybrid"
    text = (out / "hybrid.md").read_text()
    assert "## Rays for zero error" in text and "| oracle | spawn | constant bias=1 texel | 1 | 1 |" in text
    assert len(list((out / "plots").glob("hybrid_*.png"))) == 1
    assert "<section id=hybrid>" in (out / "report.html").read_text()


def test_origin_rules_across_scales():
    """The kit's spawn rule neither self-shadows nor leaks from 1e-3 to 1e6; Mitsuba's unit term
    leaks at the millimetre box's contact; an absolute 1e-4 self-shadows the tilted plane at 1e3 on."""
    from dsm.hybrid import origin_study
    rows = origin_study.table((1e-3, 1.0, 1e3, 1e6), 64)
    at = {(r["scene"], r["scale"], r["origin"]): r for r in rows}
    assert all(r["n_false_shadow"] == r["n_leak"] == 0 for r in rows if r["origin"] == "spawn")
    assert at["plane_box", 1e-3, "mitsuba"]["n_leak"] > 0 and at["plane_box", 1.0, "mitsuba"]["n_leak"] == 0
    assert at["plane", 1e3, "epsilon"]["n_false_shadow"] > 0 and at["plane", 1.0, "epsilon"]["n_false_shadow"] == 0
    assert at["plane_box", 1.0, "spawn"]["n_gt_shadowed"] > 0          # the box does cast a shadow here
    assert origin_study.markdown(rows)[0].startswith("| scene | scale |")


@pytest.mark.slow
def test_a_resumed_hybrid_run_keeps_its_cases_and_a_new_instance_is_a_new_case(tmp_path):
    """Case keys name the hybrid instance: adding a band width keeps the run's cases and measures the new one."""
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    base = dict(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": 32},
                scheme=[{"name": "constant", "bias": "1 texel"}], report={"images": "none"})
    out = tmp_path / "o"
    first = Runner(pipeline.prepare(base_config(**base, hybrid={"rule": "band", "k": [0.5, 2.0]})), out,
                   progress=False).run()
    assert len(first.rows) == 2
    again = Runner(pipeline.prepare(base_config(**base, hybrid={"rule": "band", "k": [0.5, 2.0, 8.0]})), out,
                   progress=False, resume_previous=True).run()
    assert again.run["resumed_cases"] == 2 and len(again.rows) == 3
    assert sorted(r["hybrid_params"] for r in again.rows) == ["k=0.5", "k=2.0", "k=8.0"]


@pytest.mark.slow
def test_a_hybrid_case_s_class_image_shows_v_after_its_rays(tmp_path):
    """The class image of a hybrid case holds its hybrid_* counts (V after the rays), not the map alone's: with
    `all` rays from the kit's spawn rule (V* bit for bit) no pixel is wrong, while `none`'s map alone has acne;
    with the oracle at a budget, the pixels left wrong are the hybrid's error, counted here with numpy."""
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    from dsm.truth import metrics as m
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": 64},
                      scheme=[{"name": "none"}], report={"images": "none"},
                      hybrid=[{"rule": "all"}, {"rule": "oracle", "budget": 0.01}])
    res = Runner(pipeline.prepare(cfg), tmp_path / "o", progress=False).run()
    assert len(res.rows) == 2
    for row in res.rows:
        classes = res.images[row["case"]]
        acne = int(np.isin(classes, (m.ACNE, m.ACNE_RESOLUTION)).sum())
        peterpan = int(np.isin(classes, (m.PETERPAN, m.PETERPAN_RESOLUTION, m.LEAK)).sum())
        assert (int((classes != m.OUTSIDE).sum()), acne, peterpan) == \
            (row["n_receivers"], row["hybrid_n_acne"], row["hybrid_n_peterpan"]), row["hybrid_rule"]
        assert row["n_acne"] > 0                                  # the map alone's, kept in the row's own columns
    every = next(r for r in res.rows if r["hybrid_rule"] == "all")
    assert every["hybrid_n_acne"] == every["hybrid_n_peterpan"] == 0
