"""dsm grad under an area light: the soft shadow's truth against a float64 numpy integral, Mitsuba's projective
integrator against it, the cost at equal error (its interpolation against a known curve), the new keys' errors."""
import csv
import math

import numpy as np
import pytest

from dsm.core.types import ConfigError
from dsm.grad import spec as specmod
from helpers_grad import config, toml_config

AREA = {"light": "area", "light_size": 0.5, "map_resolution": 48, "image_resolution": 48, "window": 1.0}


def _spec(**kw):
    return specmod.parse(config(**{**AREA, **kw}), "g.toml")


def _corner(X, Y, D):
    """The integral of D^2 / (D^2 + x^2 + y^2)^2 over [0, X] x [0, Y] (a point's irradiance kernel from a
    parallel rectangle at distance D), in closed form."""
    a, b = np.sqrt(D * D + X * X), np.sqrt(D * D + Y * Y)
    return 0.5 * (X / a * np.arctan(Y / a) + Y / b * np.arctan(X / b))


def _rect(x0, x1, y0, y1, D):
    return _corner(x1, y1, D) - _corner(x0, y1, D) - _corner(x1, y0, D) + _corner(x0, y0, D)


def plate_shadow_area(h, H=2.0, half=0.25, side=0.5, W=1.0, n=1024):
    """The soft shadow's area over [-W, W]^2 in float64: per receiver the plate's projection from it onto the
    light's plane, its overlap with the light, the kernel's integral over the overlap over that over the light
    (closed forms), summed over an n x n grid of receivers."""
    c = -W + (np.arange(n) + 0.5) * 2 * W / n
    rx, ry = np.meshgrid(c, c)
    k = H / h
    ox0, ox1 = np.maximum(rx + (-half - rx) * k, -side / 2), np.minimum(rx + (half - rx) * k, side / 2)
    oy0, oy1 = np.maximum(ry + (-half - ry) * k, -side / 2), np.minimum(ry + (half - ry) * k, side / 2)
    # a receiver whose overlap is empty adds 0: the kernel's integrals over the others alone (a sixth of them)
    s = (ox1 > ox0) & (oy1 > oy0)
    rx, ry, ox0, ox1, oy0, oy1 = rx[s], ry[s], ox0[s], ox1[s], oy0[s], oy1[s]
    blocked = _rect(ox0 - rx, ox1 - rx, oy0 - ry, oy1 - ry, H)
    full = _rect(-side / 2 - rx, side / 2 - rx, -side / 2 - ry, side / 2 - ry, H)
    return float(np.sum(blocked / full) * (2 * W / n) ** 2)


def test_the_corner_integral_is_the_kernels_integral():
    """The closed form the numpy reference uses, against a midpoint sum."""
    D, X, Y, n = 1.7, 0.6, -0.3, 2000
    x, y = (np.arange(n) + 0.5) / n * X, (np.arange(n) + 0.5) / n * Y
    xx, yy = np.meshgrid(x, y)
    assert _corner(X, Y, D) == pytest.approx(np.sum(D * D / (D * D + xx ** 2 + yy ** 2) ** 2) * X * Y / n / n, rel=1e-6)


def test_the_area_lights_truth_is_the_numpy_integral_within_its_own_error():
    """The soft shadow's area and its central difference in the plate's height (light samples stratified per
    receiver, the same at both heights) against the float64 integral; the point light's 2 A H^2 / (H - h)^3
    is 3.6 % off: the kernel weighs the light's near side more."""
    from dsm.grad.problem import Problem
    from dsm.grad.reference import Supersampled, reference
    spec = _spec(params=["occluder_z"], light_samples=8)
    pb = Problem(spec)
    ss = Supersampled(pb, 8, 11)
    assert ss.loss(ss.visibility(pb.values())) == pytest.approx(plate_shadow_area(0.5), rel=3e-3)
    step = spec.reference_step_of("occluder_z")
    r = reference(pb, "occluder_z", 8, step)
    want = (plate_shadow_area(0.5 + step) - plate_shadow_area(0.5 - step)) / (2 * step)
    assert r.error < 0.01 * want and abs(r.value - want) <= 3 * r.error
    assert abs(want - 2 * 0.25 * 4 / 1.5 ** 3) > 0.03 * want
    # the masked reference over every pixel is the reference
    assert r.masked(np.ones((48, 48), bool)).value == pytest.approx(r.value, rel=1e-9)


def test_the_projective_mask_leaves_the_point_lights_shadow_edge_seen():
    """The ground the camera sees holds shadow pixels (their edge): a mask over the whole shadow would make the
    projective integrator's 0 vacuous. (At 64^2 pixels: the shadow's edge, 0.333 from the centre, lies 0.08
    beyond the plate's image; two pixels of margin at 48^2 or fewer would cover it.)"""
    from dsm.grad import projective
    from dsm.grad.problem import Problem
    pb = Problem(specmod.parse(config(map_resolution=64, image_resolution=64), "g.toml"))
    seen, exact = projective.visible_ground(pb, "occluder_z"), pb.exact_image(pb.values())
    assert np.count_nonzero(seen & (exact < 1.0)) > 40


def test_equal_error_crossing_on_a_power_law():
    """A curve c / sqrt(spp) is a line in log-log: the crossing of c / sqrt(s) is s exactly; before the first
    count, after the last, and an undefined target are said as such."""
    from dsm.grad.equal_error import BELOW, NEVER, REACHED, UNDEFINED, crossing, ms_at
    spps = [1, 4, 16, 64, 256]
    errors = [0.4 / math.sqrt(s) for s in spps]
    spp, status = crossing(spps, errors, 0.4 / math.sqrt(30.0))
    assert status == REACHED and spp == pytest.approx(30.0, rel=1e-12)
    assert crossing(spps, errors, 0.5) == (1.0, BELOW)
    assert crossing(spps, errors, 0.4 / math.sqrt(1000.0)) == (None, NEVER)
    assert crossing(spps, errors, None) == (None, UNDEFINED)
    # a curve that is not monotone: the first count at or below the target
    assert crossing([1, 2, 4], [0.3, 0.1, 0.2], 0.1) == (2.0, REACHED)
    ms = [50.0 * s ** 0.5 for s in spps]
    assert ms_at(spps, ms, 30.0) == pytest.approx(50.0 * 30 ** 0.5, rel=1e-12)


def test_a_projective_run_serves_the_curve_only_at_its_own_spp_and_seeds():
    """--compare's projective run stands for a curve point only where its spp and seed count are the point's."""
    from dsm.grad.equal_error import reusable
    from dsm.grad.projective import ProjectiveResult
    res = ProjectiveResult("direct_projective", "occluder_z", 4, (0.5, 0.49), 0.0, 1.0, np.zeros((2, 2)))
    assert reusable(res, 4, 2)
    assert not reusable(res, 16, 2) and not reusable(res, 4, 3) and not reusable(None, 4, 2)


def test_spp_point_statistics_are_numpys():
    from dsm.grad.equal_error import SppPoint
    g = (0.51, 0.47, 0.5, 0.53)
    p = SppPoint("direct_projective", "occluder_z", 16, g, 0.5, 0.001, 10.0, 20.0)
    a = np.array(g)
    assert p.bias == pytest.approx(a.mean() - 0.5) and p.standard_error == pytest.approx(a.std(ddof=1) / 2)
    assert p.rel_rms_error == pytest.approx(np.sqrt(np.mean((a - 0.5) ** 2)) / 0.5)
    assert SppPoint("d", "p", 1, g, 0.0, 0.0, 1.0, 1.0).rel_rms_error is None


@pytest.mark.parametrize("kw, key, words", [
    ({"light": "point", "light_samples": 8}, "gradient.light_samples", "read only under an area light"),
    ({"light_samples": 0}, "gradient.light_samples", ">= 1"),
    ({"equal_error_spp": [16, 4]}, "gradient.equal_error_spp", "increasing"),
    ({"equal_error_spp": [4]}, "gradient.equal_error_spp", "at least two"),
    ({"equal_error_seeds": 1}, "gradient.equal_error_seeds", ">= 2"),
    ({"params": ["light_angle"]}, "gradient.params", "directional light"),
    ({"light_height": 0.5}, "light[0].position", "above the occluder"),
    ({"box_height": 0.1}, "scene[0].box_height", 'read only with builtin = "occluder_box"'),
    ({"scene": "box", "box_height": 0}, "scene[0].box_height", "> 0"),
])
def test_bad_area_light_keys_are_one_line_errors(kw, key, words):
    with pytest.raises(ConfigError) as e:
        _spec(**kw)
    msg = str(e.value)
    assert msg.startswith(f"g.toml: {key}: ") and words in msg and "\n" not in msg


@pytest.mark.slow
def test_dsm_grad_compare_under_an_area_light_measures_the_cost_at_equal_error(tmp_path):
    """direct_projective agrees with the truth over the pixels it sees; equal_error.csv holds each technique's
    match against its curve, consistent with equal_error_curve.csv; the curve's point at the projective run's
    spp and seeds is that run's gradient (the same seeds' renders)."""
    from dsm.cli import main
    from dsm.grad.equal_error import crossing
    cfg = tmp_path / "a.toml"
    cfg.write_text(toml_config(light="area", light_size=0.5, map_resolution=32, image_resolution=32,
                               techniques=["vsm"], blur=[3], antialias=[True], params=["occluder_z"],
                               reference_samples=4, light_samples=6, projective_spp=2, projective_seeds=2,
                               projective_integrators=["direct_projective"], equal_error_spp=[1, 2],
                               equal_error_seeds=2))
    assert main(["grad", str(cfg), "--compare", "--out", str(tmp_path / "o")]) == 0
    out = tmp_path / "o"
    proj = list(csv.DictReader(open(out / "projective.csv")))
    assert [p["agrees"] for p in proj] == ["True"]
    curve = list(csv.DictReader(open(out / "equal_error_curve.csv")))
    assert [int(c["spp"]) for c in curve] == [1, 2] and all(int(c["seeds"]) == 2 for c in curve)
    assert float(curve[1]["mean"]) == float(proj[0]["mean"])
    rows = list(csv.DictReader(open(out / "equal_error.csv")))
    assert len(rows) == 1 and rows[0]["technique"] == "vsm blur 3 aa"
    r = rows[0]
    spp, status = crossing([1, 2], [float(c["rel_rms_error"]) for c in curve], float(r["rel_error"]))
    assert r["status"] == status and (r["pt_spp"] == "" if spp is None else float(r["pt_spp"]) == spp)
    if r["time_ratio"]:
        assert float(r["time_ratio"]) == pytest.approx(float(r["pt_ms_per_gradient"]) / float(r["ms_per_gradient"]))
    assert (out / "equal_error.png").stat().st_size > 1000
    assert "## Cost at equal gradient error" in (out / "compare.md").read_text()


def test_every_gradient_experiment_loads():
    """experiments/gradient/*.toml are configs dsm grad accepts; the area ones light the bed with an area light."""
    from conftest import ROOT
    specs = {p.stem: specmod.load(p) for p in sorted((ROOT / "experiments" / "gradient").glob("*.toml"))}
    assert {"compare_plate_area", "compare_box_area"} <= set(specs)
    assert all(specs[n].light == "area" and specs[n].light_size == 0.5 for n in ("compare_plate_area", "compare_box_area"))
    assert specs["compare_box_area"].thickness() == 0.02 and specs["compare_plate_area"].thickness() == 0.0


def test_equal_error_figure_of_undefined_errors_says_so(tmp_path):
    """A truth of 0 over the seen pixels (the mask hides the whole shadow) leaves every relative error undefined:
    equal_error.png is drawn with that sentence in place of log axes that cannot exist (it raised before)."""
    from dsm.grad.equal_error import UNDEFINED, EqualErrorRow, SppPoint
    from dsm.grad.figure import draw_equal_error
    from dsm.grad.tables import equal_error_text
    curve = [SppPoint("direct_projective", "occluder_z", s, (0.0, 0.0), 0.0, 0.0, 5.0 * s, 9.0) for s in (1, 4)]
    assert all(q.rel_rms_error is None for q in curve)
    rows = [EqualErrorRow("pcss", "occluder_z", "direct_projective", 0.0, 0.0, None, 2.0, None, None, UNDEFINED)]
    draw_equal_error(tmp_path / "e.png", [curve], rows)
    assert (tmp_path / "e.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = equal_error_text([curve], rows)
    assert "| pcss | occluder_z | direct_projective | undefined | 2.0 | undefined | undefined | undefined |" in text


@pytest.mark.parametrize("kw, key, words", [
    ({"light_size": 2.0}, "light[0].size", "valid: 0 < size < 2)"),
    ({"light_size": 1e9, "window": 0.5}, "light[0].size", "valid: 0 < size < 1)"),
    ({"light_size": "big"}, "light[0].size", "expected a number, got 'big'"),
    ({"light_samples": 10 ** 6}, "gradient.light_samples",
     "must be <= 32, got 1000000 (valid: an integer from 1 to 32)"),
    ({"light_samples": 0}, "gradient.light_samples", "must be >= 1, got 0 (valid: an integer from 1 to 32)"),
    ({"light_samples": 2.5}, "gradient.light_samples", "expected an integer"),
    ({"equal_error_spp": [4, 4]}, "gradient.equal_error_spp", "strictly increasing counts, each from 1 to 4096"),
    ({"equal_error_spp": [0, 4]}, "gradient.equal_error_spp", ">= 1"),
    ({"equal_error_spp": [1, 10 ** 6]}, "gradient.equal_error_spp", "<= 4096"),
    ({"equal_error_spp": "16"}, "gradient.equal_error_spp", "expected an integer"),
    ({"equal_error_seeds": 10 ** 6}, "gradient.equal_error_seeds", "<= 64"),
    ({"scene": "box", "box_height": 1e9}, "light[0].position", "above the occluder's top"),
    ({"scene": "box", "box_height": "0.1"}, "scene[0].box_height", "expected a number"),
])
def test_absurd_area_light_values_are_one_line_errors(kw, key, words):
    """Huge, wrong-typed and duplicated values of the area light's keys: refused at reading, in one line."""
    with pytest.raises(ConfigError) as e:
        _spec(**kw)
    msg = str(e.value)
    assert msg.startswith(f"g.toml: {key}: ") and words in msg and "\n" not in msg


def test_compare_refuses_a_light_that_hides_the_whole_image_before_any_work(tmp_path, capsys):
    """light_size 1.95 (under 2 x window, so read) seen from the projective camera 40 windows up covers the image
    with the mask's two pixels: --compare says so in one line and writes nothing; the mask is numpy's box test."""
    from dsm.cli import main
    from dsm.grad import projective
    spec = _spec(light_size=1.95, image_resolution=16)
    half = 1.95 / 2 * 40.0 / (40.0 - spec.light_height) + 2 * 2.0 / 16      # projected half side, grown
    assert half > 1.0 and not projective.ground_seen(spec, "occluder_z").any()
    assert projective.ground_seen(_spec(light_size=0.5, image_resolution=16), "occluder_z").any()
    cfg = tmp_path / "g.toml"
    cfg.write_text(toml_config(light="area", light_size=1.95, map_resolution=16, image_resolution=16))
    assert main(["grad", str(cfg), "--compare", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"dsm: config error: {cfg}: light[0].size: --compare's projective integrators would "
                          "see no ground pixel") and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_truth_irradiance_fraction_is_the_kernels_integral_per_receiver():
    """dsm.truth.area.irradiance_fraction (the kit's rectangle, its shadow rays) at single receivers under a
    square light partly hidden by a plate, against the per-receiver float64 closed form of the kernel's
    integral over the light's unhidden part (as plate_shadow_area above); a receiver in the lit part reads 1."""
    import drjit as dr
    import mitsuba as mi
    from dsm.lights import area_surface, get
    from dsm.scenes.geometry import make_mesh, quad
    from dsm.truth.area import irradiance_fraction
    H, h, half, side = 2.0, 0.8, 0.25, 0.5
    gv, gf = quad([0.0, 0.0, 0.0], [8.0, 0.0, 0.0], [0.0, 8.0, 0.0])
    pv, pf = quad([0.0, 0.0, h], [half, 0.0, 0.0], [0.0, half, 0.0])
    scene = mi.load_dict({"type": "scene", "ground": make_mesh("ground", gv, gf), "plate": make_mesh("plate", pv, pf)},
                         optimize=False)
    light = get("area").parse({"type": "area", "shape": "rectangle", "position": [0.0, 0.0, H], "size": side},
                               "t", "light")
    rx = np.array([0.0, 0.31, -0.42, 0.36, 0.9])
    ry = np.array([0.0, 0.05, 0.38, -0.29, 0.0])
    si = dr.zeros(mi.SurfaceInteraction3f, len(rx))
    si.p = mi.Point3f(mi.Float(rx), mi.Float(ry), mi.Float(np.zeros(len(rx))))
    si.n = dr.zeros(mi.Normal3f, len(rx)) + mi.Normal3f(0.0, 0.0, 1.0)
    si.shape = mi.ShapePtr([s for s in scene.shapes() if s.id() == "ground"][0])
    got = irradiance_fraction(scene, si, si.n, area_surface.geometry(light), 32, 3, 8.0)
    rx, ry = rx.astype(np.float32).astype(float), ry.astype(np.float32).astype(float)
    k = H / h                 # the plate's projection from the receiver onto the light's plane
    ox0, ox1 = np.maximum(rx + (-half - rx) * k, -side / 2), np.minimum(rx + (half - rx) * k, side / 2)
    oy0, oy1 = np.maximum(ry + (-half - ry) * k, -side / 2), np.minimum(ry + (half - ry) * k, side / 2)
    blocked = np.where((ox1 > ox0) & (oy1 > oy0), _rect(ox0 - rx, ox1 - rx, oy0 - ry, oy1 - ry, H), 0.0)
    want = 1.0 - blocked / _rect(-side / 2 - rx, side / 2 - rx, -side / 2 - ry, side / 2 - ry, H)
    assert 0.0 < want[1:4].min() and want[1:4].max() < 1.0 and want[0] == 0.0 and want[4] == 1.0
    assert np.allclose(got, want, atol=4e-3, rtol=0.0), (got, want)
