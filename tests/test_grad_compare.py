"""dsm grad --compare / --inverse: the supersampled exact reference against closed forms, the techniques and
Mitsuba's projective integrators against it, the inverse task against the known truth."""
import csv
import math

import numpy as np
import pytest

from dsm.core.types import ConfigError
from dsm.grad import spec as specmod
from helpers_grad import config, toml_config

SMALL = {"map_resolution": 48, "image_resolution": 48, "window": 1.0}


def _spec(**kw):
    return specmod.parse(config(**{**SMALL, **kw}), "g.toml")


def test_cosine_similarity_is_the_angle_between_images():
    from dsm.grad.compare import cosine
    a = np.arange(12.0).reshape(3, 4) - 5.0
    b = np.roll(a, 1)
    assert cosine(a, a) == pytest.approx(1.0) and cosine(a, -a) == pytest.approx(-1.0)
    assert cosine(a, b) == pytest.approx(np.sum(a * b) / math.sqrt(np.sum(a * a) * np.sum(b * b)))
    assert cosine(a, np.zeros_like(a)) is None          # an all-zero gradient image: undefined, not 0


@pytest.fixture(scope="module")
def point_light():
    """The plate under the point light with PCF with and without the antialiased map, and the supersampled
    references of occluder_z and light_height (32 receivers per pixel and axis, the spec's default): the
    techniques' test and the closed forms' under this light read the same computation (the references of a
    spec with one of the parameters are these, bit for bit)."""
    from dsm.grad.compare import references
    from dsm.grad.problem import Problem
    pb = Problem(_spec(params=["occluder_z", "light_height"], techniques=["pcf_bilinear"], antialias=[False, True]))
    return pb, references(pb)


@pytest.mark.slow
@pytest.mark.parametrize("kw, param, closed", [
    ({}, "occluder_z", 2 * 0.25 * 4 / 1.5 ** 3),                                  # 2 A H^2 / (H - h)^3
    ({}, "light_height", -2 * 0.25 * 2 * 0.5 / 1.5 ** 3),                         # -2 A H h / (H - h)^3
    ({"light": "directional", "loss": "shadow_moment_x", "bias": 0.06}, "light_angle",
     0.25 * 0.5 / math.cos(math.radians(20)) ** 2 * math.pi / 180),              # A h / cos^2 per degree
])
def test_the_supersampled_reference_is_the_closed_form_within_its_own_error(kw, param, closed, point_light):
    from dsm.grad.problem import Problem
    from dsm.grad.reference import reference
    spec = _spec(params=[param], **kw)
    r = point_light[1][param] if not kw else reference(Problem(spec), param, 32, spec.reference_step_of(param))
    assert r.samples == 1024 and r.error < 0.05 * abs(closed)
    assert abs(r.value - closed) <= 3 * r.error
    assert r.image.shape == (48, 48)
    # the per-pixel image is the loss's derivative pixel by pixel (shadow area: minus the sum times a pixel)
    if spec.loss == "shadow_area":
        assert -r.image.sum() * (2.0 / 48) ** 2 == pytest.approx(r.value, rel=1e-9)


@pytest.mark.slow
def test_techniques_against_the_reference(point_light):
    """Without the antialiased map PCF sees no plate move (AD 0: sign 'zero'); with it, within 5 % of the
    truth, per-pixel gradients pointing the same way; the point light's height reverses PCF's sign."""
    from dsm.grad.compare import compare
    pb, refs = point_light
    rows = {(r.technique, r.param): r for r in compare(pb, refs)}
    raw, aa = rows["pcf_bilinear", "occluder_z"], rows["pcf_bilinear aa", "occluder_z"]
    assert raw.ad == 0.0 and raw.sign == "zero" and raw.rel_error == 1.0 and raw.cosine is None
    assert aa.rel_error < 0.05 and aa.sign == "agrees" and aa.cosine > 0.3
    assert rows["pcf_bilinear", "light_height"].sign == "opposite"
    assert all(r.ms > 0 for r in rows.values())


@pytest.mark.slow
def test_the_projective_integrator_sees_no_shadow_move_under_a_point_light():
    """Its image is the exact one (pixels the camera sees of the ground), but its gradient of the shadow's
    area in the plate's height is 0 where the truth is 2 A H^2 / (H - h)^3: a disagreement."""
    from dsm.grad import projective
    from dsm.grad.problem import Problem
    from dsm.grad.reference import reference
    from dsm.grad.tables import agrees
    spec = _spec(params=["occluder_z"], image_resolution=64)
    pb = Problem(spec)
    res = projective.gradient(pb, "direct_projective", "occluder_z", 4, 2)
    assert res.primal_mismatch < 0.01 and len(res.grads) == 2
    assert np.count_nonzero(res.seen & (pb.exact_image(pb.values()) < 1.0)) > 40     # it sees the shadow's edge
    assert res.mean == 0.0
    ref = reference(pb, "occluder_z", 16, spec.reference_step_of("occluder_z"))
    assert ref.value == pytest.approx(2 * 0.25 * 4 / 1.5 ** 3, rel=0.05)
    seen = ref.masked(res.seen)            # the truth over the pixels the integrator measures: far from 0
    assert seen.value > 10 * seen.error and not agrees(res, seen)


@pytest.mark.slow
def test_the_inverse_task_recovers_the_plates_height_through_the_antialiased_map():
    from dsm.grad.inverse import inverse_problem, descend
    from dsm.grad.problem import Problem
    from dsm.grad.spec import Technique
    spec = _spec(params=["occluder_z"], inverse_starts=[-0.05, 0.05], inverse_iterations=30)
    inv = inverse_problem(Problem(spec), "occluder_z")
    for off in (-0.05, 0.05):
        run = descend(inv, Technique("vsm", 3, True), "occluder_z", off)
        assert run.success and run.final_error < 0.01 and run.converged_at is not None
        stuck = descend(inv, Technique("pcf_bilinear", 1, False), "occluder_z", off)
        # a gradient of 0 never moves the parameter (mi.ad.Adam holds it in float32)
        assert set(stuck.trace) == {float(np.float32(off))} and not stuck.success and stuck.converged_at is None


@pytest.mark.slow
def test_dsm_grad_compare_writes_its_tables_and_refuses_the_l2_loss(tmp_path, capsys):
    from dsm.cli import main
    bad = tmp_path / "bad.toml"
    bad.write_text(toml_config(loss="l2", target={"occluder_z": 0.05}))
    assert main(["grad", str(bad), "--compare", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "gradient.loss" in err and "shadow_area" in err
    good = tmp_path / "good.toml"
    good.write_text(toml_config(map_resolution=24, image_resolution=16, techniques=["pcf_bilinear"], antialias=[True],
                                params=["occluder_z"], reference_samples=8, projective_spp=2,
                                projective_integrators=["direct_projective"], projective_seeds=1,
                                inverse_starts=[0.05], inverse_iterations=3))
    assert main(["grad", str(good), "--compare", "--inverse", "--out", str(tmp_path / "g")]) == 0
    out = tmp_path / "g"
    rows = list(csv.DictReader(open(out / "compare.csv")))
    assert len(rows) == 1 and rows[0]["technique"] == "pcf_bilinear aa" and float(rows[0]["ms_per_gradient"]) > 0
    proj = list(csv.DictReader(open(out / "projective.csv")))
    assert [p["integrator"] for p in proj] == ["direct_projective"]
    inv = list(csv.DictReader(open(out / "inverse.csv")))
    assert len(inv) == 1 and inv[0]["start_offset"] == "0.05"
    assert (out / "gradients.png").stat().st_size > 1000 and "Inverse task" in (out / "inverse.md").read_text()


def test_a_mesh_occluder_is_scaled_to_its_size_and_set_on_its_height(tmp_path):
    from conftest import ROOT
    from dsm.grad.occluder import shapes
    with pytest.raises(ConfigError) as e:
        specmod.parse(config(scene="mesh", mesh="nowhere.ply"), str(tmp_path / "g.toml"))
    assert "scene[0].mesh: no such file" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ConfigError) as e:
        specmod.parse(config(mesh="a.ply"), "g.toml")
    assert str(e.value).startswith('g.toml: scene[0].mesh: is read only with builtin = "occluder_mesh"')
    spec = specmod.parse(config(scene="mesh", mesh=str(ROOT / "data/meshes/mitsuba_bunny.ply"), occluder_size=0.4,
                                occluder_height=0.3), "g.toml")
    v, f = shapes(spec)["occluder"]         # the kit's occluder_mesh built-in
    ext = v.max(axis=0) - v.min(axis=0)
    assert ext.max() == pytest.approx(0.4) and v[:, 2].min() == pytest.approx(0.3)
    assert (v[:, 0].max() + v[:, 0].min()) == pytest.approx(0.0, abs=1e-9) and f.max() < len(v)
