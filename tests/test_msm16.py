"""MSM's optimized 16-bit quantization ([map] format = "unorm16"; Peters & Klein 2015, "Optimized
Moment Quantization"): the transform and its inverse against the published constants in numpy float64, the restored
moments' error against the analytic bound of the rounding, the lookup beside float32 on the
builtin plates (and raw float16 power moments beside it), and what the config refuses."""
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import base_config

# typed again from Shadows/MSM.hlsl (TheRealMJP/Shadows, 37b61461): GetOptimizedMoments (HLSL
# row-vector convention, q = b M + offset) and ConvertOptimizedMoments (its printed inverse)
PAPER_M = np.array([[-2.07224649, 13.7948857237, 0.105877704, 9.7924062118],
                    [32.23703778, -59.4683975703, -1.9077466311, -33.7652110555],
                    [-68.571074599, 82.0359750338, 9.3496555107, 47.9456096605],
                    [39.3703274134, -35.364903257, -6.6543490743, -23.9728048165]])
PAPER_OFFSET = np.array([0.035955884801, 0.0, 0.0, 0.0])
PAPER_INVERSE = np.array([[0.2227744146, 0.1549679261, 0.1451988946, 0.163127443],
                          [0.0771972861, 0.1394629426, 0.2120202157, 0.2591432266],
                          [0.7926986636, 0.7963415838, 0.7258694464, 0.6539092497],
                          [0.0319417555, -0.1722823173, -0.2758014811, -0.3376131734]])
STEP = 1.0 / 65535.0


def _powers(t):
    """The power moments (t, t^2, t^3, t^4) as rows, numpy float64."""
    return np.stack([t, t ** 2, t ** 3, t ** 4], axis=1)


def test_the_transform_is_the_papers_and_its_inverse_round_trips():
    from dsm.prefilter import msm
    t = np.linspace(0.0, 1.0, 2001)
    q = np.stack(msm.encode(t, msm.Params()), axis=1)
    want = _powers(t) @ PAPER_M + PAPER_OFFSET
    assert np.abs(q - want).max() < 1e-12
    back = np.stack(msm.decode(list(q.T)), axis=1)
    assert np.abs(back - _powers(t)).max() < 1e-12
    assert np.abs(msm.DEQUANTIZATION_MATRIX - PAPER_INVERSE).max() < 1e-9     # its 10 printed digits
    # the image of [0, 1]'s moments fits a unorm (the offset's purpose), up to float64 rounding of the constants
    assert q.min() > -1e-7 and q.max() < 1.0 + 1e-7


def _one_face(R):
    """A one-face view of normalized depth (near 0, far 1)."""
    return SimpleNamespace(near=0.0, far=1.0, faces=1, resolution=R, R_u=dr.opaque(mi.UInt32, R))


def _box3(x):
    """The 3 x 3 box mean of an image, edge texels repeated (numpy float64, written out)."""
    p = np.pad(x, 1, mode="edge")
    R = x.shape[0]
    return sum(p[i:i + R, j:j + R] for i in range(3) for j in range(3)) / 9.0


@pytest.mark.parametrize("blur", [1, 3])
def test_restored_moments_err_within_the_rounding_bound(blur):
    """Each stored q is within half a step of its exact value (W = 1), or one step after the
    blur's second rounding (the first rounding's error averaged, then rounded again): the
    restored moment b_j errs by at most sum_i |Theta^-1_ij| times that (plus float32's reading
    of k / 65535). The bound is met, and nearly reached (it is not loose by orders)."""
    from dsm.prefilter import base, msm
    R = 48
    rng = np.random.default_rng(16)
    t = rng.uniform(0.0, 1.0, (R, R))
    mmap = base.build(msm, msm.Params(), t.ravel(), _one_face(R), "unorm16", blur)
    q = [np.asarray(b.numpy(), np.float64) for b in mmap.b]
    assert all(np.allclose(x * 65535.0, np.round(x * 65535.0), atol=1e-2) for x in q)   # k / 65535 as float32 holds it
    got = np.stack(msm.decode(q), axis=1)
    exact = _powers(t.ravel()) if blur == 1 else np.stack([_box3(m.reshape(R, R)).ravel() for m in _powers(t.ravel()).T], 1)
    rounding = 0.5 * STEP if blur == 1 else STEP
    bound = np.abs(PAPER_INVERSE).sum(axis=0) * (rounding + 2.0 ** -24)
    err = np.abs(got - exact).max(axis=0)
    assert (err <= bound).all() and (err > 0.2 * bound).all(), (err, bound)


def test_far_moments_are_the_encoded_moments_of_t_1():
    from dsm.prefilter import base, msm
    mmap = base.build(msm, msm.Params(), np.full(16, 0.5), _one_face(4), "unorm16", 1)
    want = np.clip(np.ones(4) @ PAPER_M + PAPER_OFFSET, 0.0, 1.0)
    assert np.abs(np.array(mmap.far_b) - np.round(want * 65535) / 65535).max() < 1e-15


def _plate_lookups(scene, blur, R=128, cam=128):
    """V per receiver of msm (default bias 3e-5) in each moment format, and V* (one scene, its sun)."""
    import dsm.pipeline as pl
    from dsm.prefilter import msm
    from dsm.core.types import MomentSpec
    sd = pl.load_scene(pl.scene_spec({"builtin": scene}), (cam, cam))
    setup = pl.light_setup(sd, pl.gbuffer(sd), sd.own_lights[0], "sun")
    view = pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    rx = pl.receivers(view, setup, sd.diagonal)
    spec = MomentSpec("msm", msm.Params(), blur)
    v = {f: pl.moment_visibility(spec, rx, pl.moment_map(spec, smap, f), smap)[0].numpy().astype(np.float64)
         for f in ("float32", "unorm16", "float16")}
    return v, setup.v_star


@pytest.mark.parametrize("scene", ["stacked_plates", "floating_plate"])
@pytest.mark.parametrize("blur", [3, 5])
def test_unorm16_lookup_decides_as_float32_and_raw_float16_errs_more(scene, blur):
    """The paper's point: with the optimized quantization, at the default moment bias 3e-5, the
    blurred 4MSM lookup stays defined and decides (V >= 0.5) as in float32 on >= 99.9 % of
    receivers; raw float16 power moments move V further from float32's (mean |V - V_f32|).
    Unblurred (W = 1) floating_plate is left out: there each receiver's texel holds one depth,
    its own, and the bias of 3e-5 leaves its decision on a knife edge (float32 itself errs on 6 %
    of receivers at R = 128), so any rounding flips some (unorm16 agrees on 98.4 %, float16 93.7 %)."""
    v, _ = _plate_lookups(scene, blur)
    ref = v["float32"] >= 0.5
    assert np.isfinite(v["unorm16"]).all()
    assert np.mean((v["unorm16"] >= 0.5) == ref) >= 0.999
    dev = {f: np.abs(v[f] - v["float32"]).mean() for f in ("unorm16", "float16")}
    assert dev["float16"] > 2.0 * dev["unorm16"], dev


# ---------------------------------------------------------------- config and run

@pytest.mark.parametrize("kind", ["vsm", "esm", "evsm"])
def test_the_kinds_without_an_encoding_refuse_unorm16_naming_map_format(kind):
    from dsm.config import read as config
    cfg = base_config(map={"resolution": 32, "kind": ["depth", kind, "msm"], "format": ["float32", "unorm16"]})
    with pytest.raises(config.ConfigError) as e:
        config.parse(cfg, "exp.toml")
    msg = str(e.value)
    assert e.value.key == "map.format" and "\n" not in msg
    assert msg.startswith("exp.toml: map.format:") and kind in msg and e.value.choices == ("float32", "float16")


def test_unorm16_msm_is_planned_and_run_and_the_depth_cases_keep_their_unorm16(run_dict):
    """[map] format = ["float32", "unorm16"] with depth and msm: the depth cases quantize the depth
    as before, the msm cases store the optimized moments; each row checks and names its format."""
    from dsm.config import read as config
    from dsm.config import plan
    from dsm.core import record
    cfg = base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [32, 32]},
                      map={"resolution": 32, "kind": ["depth", "msm"], "blur": [1, 3], "format": ["float32", "unorm16"]})
    assert plan.make(config.parse(cfg, "<test>")).cases == 2 + 2 * 2
    res = run_dict(cfg)
    got = sorted((r["map_kind"], r["filter"], r["format"]) for r in res.rows)
    assert got == sorted([("depth", "nearest", f) for f in ("float32", "unorm16")]
                         + [("msm", f"box:{w}", f) for w in (1, 3) for f in ("float32", "unorm16")])
    for r in res.rows:
        assert record.check_row(r) is r and r["n_peterpan_edge"] + r["n_leak"] == r["n_peterpan"]
