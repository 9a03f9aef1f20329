"""Pre-filtered shadow maps (dsm.prefilter): each kind's lookup against a numpy float64
computation, the blur against explicit windows, the classic VSM leak of stacked occluders
derived by hand, the unfiltered VSM that must not leak, the leak split, and a run's rows."""
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import base_config

RNG = np.random.default_rng(30)


def _prm(**kw):
    """Parameters as the lookup gets them: opaque float32 values."""
    return SimpleNamespace(**{k: dr.opaque(mi.Float, float(v)) for k, v in kw.items()})


def _f(x):
    return mi.Float(np.asarray(x, np.float32))


def _np(x):
    return np.asarray(x.numpy(), np.float64)


# ---------------------------------------------------------------- Chebyshev (VSM) against float64

def test_vsm_is_chebyshevs_bound_as_numpy_float64_computes_it():
    from dsm.prefilter import vsm
    n = 4000
    mean = RNG.uniform(0.05, 0.95, n)
    var = RNG.uniform(0.0, 0.02, n)
    t = RNG.uniform(0.0, 1.0, n)
    mean_sq = mean * mean + var
    mv, bleed = 1e-3, 0.2
    v = _np(vsm.visibility([_f(mean), _f(mean_sq)], _f(t), _prm(min_variance=mv, bleed=bleed, bleed_high=1.0)))
    # the float64 reference: one-sided Chebyshev (Cantelli) P(z >= t) <= s^2 / (s^2 + (t - mu)^2)
    m32, s32, t32 = (np.float32(a).astype(np.float64) for a in (mean, mean_sq, t))
    s2 = np.maximum(s32 - m32 ** 2, mv)
    p = np.where(t32 <= m32, 1.0, s2 / (s2 + (t32 - m32) ** 2))
    want = np.clip((p - bleed) / (1 - bleed), 0, 1)
    # float32 cancellation of E[z^2] - E[z]^2 is ~1e-7 absolute, divided by var >= 1e-3
    assert np.abs(v - want).max() < 2e-4
    assert (want < 0.5).any() and (want > 0.5).any()        # both sides of the lit test are exercised


# ---------------------------------------------------------------- MSM Hamburger 4MSM against float64

def _hamburger_np(b, t, alpha):
    """Peters & Klein 2015, algorithm 2, in float64 with numpy's solver and roots (not the
    kit's Cholesky): V = 1 - G for biased moments b' = (1 - a) b + a 0.5."""
    out = np.empty(len(t))
    for k in range(len(t)):
        b1, b2, b3, b4 = (1 - alpha) * b[:, k] + alpha * 0.5
        B = np.array([[1, b1, b2], [b1, b2, b3], [b2, b3, b4]])
        c = np.linalg.solve(B, [1.0, t[k], t[k] ** 2])
        z2, z3 = np.sort(np.roots([c[2], c[1], c[0]]).real)
        zf = t[k]
        if zf <= z2:
            g = 0.0
        elif zf <= z3:
            g = (zf * z3 - b1 * (zf + z3) + b2) / ((z3 - z2) * (zf - z2))
        else:
            g = 1.0 - (z2 * z3 - b1 * (z2 + z3) + b2) / ((zf - z2) * (zf - z3))
        out[k] = 1.0 - np.clip(g, 0, 1)
    return out


def test_msm_hamburger_4msm_matches_numpy_float64():
    from dsm.prefilter import msm
    n = 400
    # moments of three-point depth distributions (a blurred window over three casters)
    z = RNG.uniform(0.1, 0.9, (3, n))
    w = RNG.dirichlet([1, 1, 1], n).T
    b = np.stack([(w * z ** k).sum(0) for k in (1, 2, 3, 4)])
    t = RNG.uniform(0.05, 0.95, n)
    alpha = 2e-3          # large enough that float32's Cholesky stays within 1e-3 of float64's
    b32 = np.float32(b).astype(np.float64)
    t32 = np.float32(t).astype(np.float64)
    v = _np(msm.visibility([_f(x) for x in b], _f(t), _prm(moment_bias=alpha, depth_bias=0.0)))
    want = _hamburger_np(b32, t32, alpha)
    assert np.abs(v - want).max() < 2e-3
    assert (want < 0.2).any() and (want > 0.8).any()


def test_msm_lights_a_receiver_in_front_of_every_caster_and_shadows_one_behind():
    from dsm.prefilter import msm
    b = [_f([m] * 2) for m in (0.4, 0.4 ** 2, 0.4 ** 3, 0.4 ** 4)]     # one caster at t = 0.4
    v = _np(msm.visibility(b, _f([0.2, 0.8]), _prm(moment_bias=3e-5, depth_bias=0.0)))
    assert v[0] == pytest.approx(1.0, abs=1e-3) and v[1] < 0.05


# ---------------------------------------------------------------- ESM, EVSM against float64

def test_esm_is_the_exponential_test_of_the_filtered_moment():
    from dsm.prefilter import esm
    c = 40.0
    z = RNG.uniform(0.1, 0.9, 500)
    t = RNG.uniform(0.0, 1.0, 500)
    v = _np(esm.visibility([_f(np.exp(c * z))], _f(t), _prm(c=c)))
    want = np.clip(np.exp(-c * (np.float32(t) - np.float32(z))), 0, 1)   # exp(c z) exp(-c t), float64
    assert np.abs(v - want).max() < 1e-4 * c


@pytest.mark.parametrize("count", [2, 4])
def test_evsm_is_the_smaller_warped_chebyshev_bound(count):
    from dsm.prefilter import evsm
    cp, cn, mv = 5.0, 3.0, 1e-4
    p = evsm.Params(positive=cp, negative=cn, moments=count, min_variance=mv)
    # a window of two casters: the exact warped moments of its mixture
    za, zb, f = RNG.uniform(0.1, 0.5, 300), RNG.uniform(0.5, 0.9, 300), RNG.uniform(0, 1, 300)
    moms = [f * a + (1 - f) * b_ for a, b_ in zip(evsm.moments(za, p), evsm.moments(zb, p))]
    t = RNG.uniform(0.0, 1.0, 300)
    v = _np(evsm.visibility([_f(m) for m in moms], _f(t), _prm(positive=cp, negative=cn, min_variance=mv, bleed=0.0)))
    x = 2 * np.float32(t).astype(np.float64) - 1
    m32 = [np.float32(m).astype(np.float64) for m in moms]

    def cheb(m1, m2, d, slope):
        var = np.maximum(m2 - m1 ** 2, mv * slope ** 2)
        return np.where(d <= m1, 1.0, var / (var + (d - m1) ** 2))
    want = cheb(m32[0], m32[1], np.exp(cp * x), 2 * cp * np.exp(cp * x))
    if count == 4:
        want = np.minimum(want, cheb(m32[2], m32[3], -np.exp(-cn * x), 2 * cn * np.exp(-cn * x)))
    assert np.abs(v - want).max() < 5e-4


# ---------------------------------------------------------------- storage and blur

def test_box_blur_is_the_mean_over_the_window_clamped_at_the_face_edge():
    from dsm.prefilter.base import box_blur
    faces, R, W = 2, 7, 5
    x = RNG.uniform(0, 1, faces * R * R)
    got = box_blur(x, W, faces, R).reshape(faces, R, R)
    img = x.reshape(faces, R, R)
    h = W // 2
    for f in range(faces):          # explicit windows, indices clamped to the face (never the other face)
        for j in range(R):
            for i in range(R):
                rows = np.clip(np.arange(j - h, j + h + 1), 0, R - 1)
                cols = np.clip(np.arange(i - h, i + h + 1), 0, R - 1)
                assert got[f, j, i] == pytest.approx(img[f][np.ix_(rows, cols)].mean(), abs=1e-12)


def test_gaussian_blur_is_the_weighted_window_of_sigma_w_plus_1_over_6():
    """Each texel is the 2D Gaussian-weighted mean of its W x W window (sigma = (W + 1) / 6, the
    weights normalized over the window, indices clamped to the face), computed here window by
    window with an explicit outer-product kernel."""
    from dsm.prefilter.base import gaussian_blur
    faces, R, W = 2, 7, 5
    x = RNG.uniform(0, 1, faces * R * R)
    got = gaussian_blur(x, W, faces, R).reshape(faces, R, R)
    img = x.reshape(faces, R, R)
    h, sigma = W // 2, (W + 1) / 6
    k = np.arange(-h, h + 1)
    g = np.exp(-(k[:, None] ** 2 + k[None, :] ** 2) / (2 * sigma ** 2))
    g /= g.sum()
    for f in range(faces):
        for j in range(R):
            for i in range(R):
                rows = np.clip(np.arange(j - h, j + h + 1), 0, R - 1)
                cols = np.clip(np.arange(i - h, i + h + 1), 0, R - 1)
                assert got[f, j, i] == pytest.approx((img[f][np.ix_(rows, cols)] * g).sum(), abs=1e-12)
    assert np.array_equal(gaussian_blur(x, 1, faces, R), x)


def test_blur_kernel_sweeps_and_names_the_filter_column():
    """[map] blur_kernel sweeps box and gaussian (the filter column box:W / gauss:W); a bad value
    or a kernel without a pre-filtered kind is one error naming map.blur_kernel."""
    from dsm.config import read as config
    cfg = config.parse(base_config(map={"kind": ["depth", "vsm"], "blur": [1, 5],
                                        "blur_kernel": ["box", "gaussian"]}), "<test>")
    assert [m.filter for m in cfg.map.moments] == ["box:1", "gauss:1", "box:5", "gauss:5"]
    for m in ({"kind": ["depth", "vsm"], "blur_kernel": "tent"}, {"blur_kernel": "gaussian"}):
        with pytest.raises(config.ConfigError) as e:
            config.parse(base_config(map=m), "<test>")
        assert e.value.key == "map.blur_kernel"


def test_box_blur_keeps_the_small_values_of_an_exponential_moment():
    """A running sum would lose exp(8) next to exp(80) (30 decades); the window's own sum keeps it."""
    from dsm.prefilter.base import box_blur
    x = np.full(9 * 9, np.exp(8.0))
    x[:9] = np.exp(80.0)                # the first row
    got = box_blur(x, 3, 1, 9).reshape(9, 9)
    assert got[4, 4] == pytest.approx(np.exp(8.0), rel=1e-12)


def test_float16_storage_rounds_as_ieee_half():
    from dsm.prefilter.base import stored
    x = np.array([0.1, 1 / 3, 1000.1, 70000.0])
    assert list(stored(x, "float16")) == [float(np.float16(0.1)), float(np.float16(1 / 3)), 1000.0, np.inf]
    assert stored(np.array([1 / 3]), "float32")[0] == float(np.float32(1 / 3))


def test_float16_depth_format_stores_the_normalized_depth_as_a_half():
    from dsm.maps import formats
    view = SimpleNamespace(near=0.0, far=10.0, kind="orthographic", n_texels=3)
    q = formats.quantize_np(np.array([1.0, 3.3333, 9.99]), view, "float16")
    want = [10 * float(np.float16(0.1)), 10 * float(np.float16(0.33333)), 10 * float(np.float16(0.999))]
    assert q == pytest.approx(want, rel=1e-12)


# ---------------------------------------------------------------- a synthetic map: the classic leak

def _synthetic(R):
    """A one-face view of normalized depth (near 0, far 1) and a receiver at every texel centre."""
    view = SimpleNamespace(near=0.0, far=1.0, faces=1, resolution=R, R_u=dr.opaque(mi.UInt32, R))
    jj, ii = np.meshgrid(np.arange(R), np.arange(R), indexing="ij")
    rx = SimpleNamespace(u_map=_f(ii.ravel() + 0.5), v_map=_f(jj.ravel() + 0.5),
                         face=dr.zeros(mi.UInt32, R * R), depth=None)
    return view, rx


def _vsm_map(z1, R, blur, mv, receiver_t):
    from dsm import prefilter
    from dsm.prefilter import vsm
    from dsm.core.types import MomentSpec
    view, rx = _synthetic(R)
    rx.depth = _f(np.full(R * R, receiver_t))
    spec = MomentSpec("vsm", vsm.Params(min_variance=mv), blur)
    mmap = prefilter.build(spec, z1, view, "float32")
    return _np(prefilter.visibility(spec, rx, mmap)).reshape(R, R)


@pytest.mark.parametrize("blur", [1, 3, 5])
def test_stacked_occluders_leak_where_the_window_straddles_them_derived_by_hand(blur):
    """Columns u < 8 see a near occluder A at t_A = 0.1 (with B under it), columns u >= 8 the
    plate B at t_B = 0.5; the ground receiver at d = 0.55 is shadowed everywhere (V* = 0).

    A window holding a fraction f of A has mean mu = t_B - f D (D = t_B - t_A = 0.4) and variance
    f (1 - f) D^2, so Chebyshev gives p = f(1-f) D^2 / (f(1-f) D^2 + (d - t_B + f D)^2), and
    p >= 0.5 (lit: a leak) exactly when f(1-f) D^2 >= (d - t_B + f D)^2, i.e. with D = 0.4 and
    d - t_B = 0.05: 0.16 f (1 - f) >= (0.05 + 0.4 f)^2, i.e. 0.32 f^2 - 0.12 f + 0.0025 <= 0:
    f in [0.0215, 0.3535]. f = 0 (all B) and f = 1 (all A) give p = min_variance-limited ~ 0.
    A box of width W centred on column u holds f = (8 - (u - h)) / W of A for the columns whose
    window straddles the edge (h = W // 2): W = 1 never straddles (no leak); W = 3: f = 1/3 at
    u = 8 only (2/3 at u = 7 is outside the interval); W = 5: f = 1/5 at u = 9 and 2/5 at u = 8
    (0.4 > 0.3535): so only column 9."""
    R = 16
    z1 = np.where(np.arange(R)[None, :] < 8, 0.1, 0.5) * np.ones((R, 1))
    v = _vsm_map(z1.ravel(), R, blur, 1e-6, 0.55)
    leak_cols = sorted(set(np.nonzero(v >= 0.5)[1]))
    expected = {1: [], 3: [8], 5: [9]}[blur]
    assert leak_cols == expected
    assert all((v[:, c] >= 0.5).all() for c in expected)         # the whole column (the edge is along v)


def test_unfiltered_vsm_under_one_planar_occluder_does_not_leak():
    """One plate at t = 0.3 over every texel; receivers g behind it. With W = 1 the texel's
    variance is 0, clamped to min_variance s^2, so p = s^2 / (s^2 + g^2) < 0.5 iff g > s: a gap
    larger than sqrt(min_variance) leaves no receiver lit, and one just below it lights them."""
    R, mv = 8, 1e-4
    s = np.sqrt(mv)
    z1 = np.full(R * R, 0.3)
    assert (_vsm_map(z1, R, 1, mv, 0.3 + 1.05 * s) < 0.5).all()
    assert (_vsm_map(z1, R, 1, mv, 0.3 + 0.95 * s) >= 0.5).all()


# ---------------------------------------------------------------- the leak split

def test_leak_split_by_where_the_false_light_is_in_the_shadow():
    from dsm.truth import metrics
    v = np.array([1.0, 0.6, 0.7, 0.2, 1.0, 0.0])
    v_star = np.array([False, False, False, False, True, False])
    deep = np.array([False, True, True, True, False, True])      # inside the exact shadow by k texels or more
    out = metrics.leak_split(v, v_star, deep)
    # false light: receivers 0 (at the shadow's edge), 1 and 2 (deep: leaks); 3 and 5 are dark, 4 truly lit
    assert out == {"n_peterpan_edge": 1, "n_leak": 2, "peterpan_edge_rate": 1 / 5, "leak_rate": 2 / 5}
    none = metrics.leak_split(v[4:5], v_star[4:5], deep[4:5])
    assert np.isnan(none["leak_rate"]) and none["n_leak"] == 0   # nothing shadowed: the rate is undefined
    soft = metrics.leak_split(v, v_star, None)                    # an area light: undefined, not 0
    assert all(np.isnan(x) for x in soft.values())


# ---------------------------------------------------------------- config

@pytest.mark.parametrize("m, key", [
    ({"kind": "vsx"}, "map.kind"),
    ({"kind": "vsm", "format": "unorm24"}, "map.format"),
    ({"kind": "vsm", "blur": 4}, "map.blur"),
    ({"blur": 3}, "map.blur"),
    ({"esm": {"c": 10}}, "map.esm"),
    ({"kind": "evsm", "evsm": {"moments": 3}}, "map.evsm.moments"),
    ({"kind": "esm", "esm": {"c": 20}, "format": "float16"}, "map.esm"),
    ({"kind": "evsm", "evsm": {"positive": 40}, "format": "float16"}, "map.evsm"),
    ({"kind": "vsm", "vsm": {"bleed": 1.5}}, "map.vsm.bleed"),
    ({"kind": "vsm", "cascades": 2}, "map.cascades"),
    ({"kind": "vsm", "filter": "pcf_wide:5"}, "map.filter"),
    ({"leak_texels": 3}, "map.leak_texels"),
    ({"kind": "vsm", "blur": 65}, "map.blur"),
    ({"kind": "vsm", "vsm": 5}, "map.vsm"),
])
def test_bad_map_kind_input_is_one_config_error_naming_the_key(m, key):
    from dsm.config import read as config
    cfg = base_config(map={"resolution": 32, **m})
    if m.get("kind") == "vsm":
        del cfg["scheme"]            # schemes are the depth kind's
    with pytest.raises(config.ConfigError) as e:
        config.parse(cfg, "<test>")
    assert e.value.key == key and "\n" not in str(e.value)


def test_schemes_belong_to_the_depth_kind():
    from dsm.config import read as config
    with pytest.raises(config.ConfigError) as e:
        config.parse(base_config(map={"kind": "vsm"}), "<test>")
    assert e.value.key == "scheme"
    cfg = base_config(map={"kind": "vsm"})
    del cfg["scheme"]
    assert config.parse(cfg, "<test>").schemes == ()


def test_plan_counts_the_moment_cases_and_resume_keys_them():
    from dsm.config import read as config
    from dsm.config import plan
    from dsm.experiment import resume
    cfg = config.parse(base_config(map={"resolution": 32, "kind": ["depth", "vsm", "msm"], "blur": [1, 3],
                                        "format": ["float32", "float16"], "vsm": {"min_variance": [1e-4, 1e-3]},
                                        "filter": ["nearest", "pcf_bilinear"]},
                                   scheme=[{"name": "none"}, {"name": "dual", "culling": "back"}]), "<test>")
    p = plan.make(cfg)
    # depth: 2 schemes x 2 filters x 2 formats; moments: (2 vsm + 1 msm) x 2 blurs x 2 formats, on the culling-none map
    assert p.cases == 2 * 2 * 2 + 3 * 2 * 2
    assert [len(m.moments) for m in p.maps] == [6, 0]
    keys = resume.case_keys(cfg, p, "v")
    assert len(keys) == p.cases and len({k for _, k in keys}) == p.cases


def test_without_kind_the_plan_and_rows_are_unchanged():
    from dsm.config import read as config
    from dsm.config import plan
    cfg = config.parse(base_config(), "<test>")
    assert cfg.map.kind == ("depth",) and not cfg.map.leak_split and cfg.map.moments == ()
    assert all(m.moments == () for m in plan.make(cfg).maps)


# ---------------------------------------------------------------- a run

@pytest.mark.slow
def test_a_run_of_floating_plate_measures_each_kind_and_vsm_unfiltered_is_a_constant_bias(run_dict):
    """floating_plate (a plate 0.2 above the ground), every kind at W = 1 and 5: each row has the
    prefilter group, its contact and leak add up to n_peterpan. The unfiltered VSM lights a
    receiver g behind its texel exactly when g^2 <= min_variance (normalized depth): the depth
    test with a constant bias of sqrt(min_variance) depth ranges, here 0.01 range, so the two
    cases classify every pixel alike."""
    from dsm.core import record
    res = run_dict(base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [64, 64]},
                               map={"resolution": 64, "kind": ["depth", "vsm", "esm", "evsm", "msm"], "blur": [1, 5],
                                    "vsm": {"min_variance": 1e-4}, "esm": {"c": 40}, "evsm": {"positive": 20}},
                               scheme=[{"name": "constant", "bias": "0.01 range"}]))
    rows = {(r["scheme"], r["filter"]): r for r in res.rows}
    assert len(res.rows) == 1 + 4 * 2
    for r in res.rows:
        assert record.check_row(r) is r
        assert set(r) == (record.GROUPS["core"] | record.GROUPS["map"] | record.GROUPS["prefilter"]
                          | record.GROUPS["precision"] | record.GROUPS["cost"])
        assert r["n_peterpan_edge"] + r["n_leak"] == r["n_peterpan"]
        assert (r["map_kind"] == "depth") == (r["scheme"] == "constant")
        assert np.isnan(r["moments_ms"]) == (r["map_kind"] == "depth")
    depth, vsm1 = rows[("constant", "nearest")], rows[("vsm", "box:1")]
    assert depth["n_acne"] == vsm1["n_acne"] and depth["n_peterpan"] == vsm1["n_peterpan"]
    from dsm.truth import metrics
    from dsm.truth.metrics import base_class
    assert (base_class(res.images[depth["case"]]) == base_class(res.images[vsm1["case"]])).all()   # the same class
    assert (res.images[depth["case"]] == metrics.LEAK).sum() == depth["n_leak"]      # the leaks in their own colour
    assert (res.images[vsm1["case"]] == metrics.LEAK).sum() == vsm1["n_leak"]
    assert vsm1["mean_abs_error"] >= depth["mean_abs_error"]    # V continuous: errs by its soft values too


def test_unfiltered_vsm_is_the_constant_bias_receiver_by_receiver_and_lights_nothing_under_the_plate():
    """Stage by stage on floating_plate: per receiver, V_vsm >= 0.5 iff the constant bias of
    sqrt(min_variance) ranges lights it; among the receivers the exact visibility shadows whose
    nearest texel is the plate (its gap 0.2 world is > sqrt(min_variance) ranges), none is lit."""
    import dsm.pipeline as pl
    from dsm.core.types import MomentSpec
    from dsm.prefilter import vsm
    sd = pl.load_scene(pl.scene_spec({"builtin": "floating_plate", "gap": 0.2}), (64, 64))
    setup = pl.light_setup(sd, pl.gbuffer(sd), sd.own_lights[0], "sun")
    view = pl.make_view(setup.light, 64, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    rx = pl.receivers(view, setup, sd.diagonal)
    mv = 1e-4
    assert 0.2 > np.sqrt(mv) * view.depth_range          # the gap exceeds the VSM's own bias
    spec = MomentSpec("vsm", vsm.Params(min_variance=mv), 1)
    v, shape = pl.moment_visibility(spec, rx, pl.moment_map(spec, smap, "float32"), smap)
    v_depth, _ = pl.visibility(pl.scheme_spec({"name": "constant", "bias": "0.01 range"}), rx, smap)
    v, shape, v_depth = v.numpy(), shape.numpy(), v_depth.numpy()
    assert ((v >= 0.5) == (v_depth >= 0.5)).all()
    plate = sd.shape_names.index("plate")
    under = ~setup.v_star & (shape == plate)
    assert under.sum() > 20 and (v[under] < 0.5).all()


def test_stacked_plates_leak_in_the_one_texel_column_derived_by_hand():
    """stacked_plates, light straight down: the high plate (x in [-0.75, 0], height 2) over half
    of the low one (|x|, |y| <= 0.75, height 0.25) over the ground. In normalized depth the
    ground is g = 0.25 / range behind the low plate and the low plate D = 1.75 / range behind the
    high one (r = g / D = 1/7). A ground receiver under the low plate alone whose W = 5 window
    holds a fraction f of high-plate texels is lit (p >= 0.5) exactly when f(1-f) D^2 >= (g + f D)^2,
    i.e. 2 f^2 - (1 - 2r) f + r^2 <= 0: f in [0.031, 0.326]. The window of column i_h + k (i_h:
    the last column whose centre ray meets the high plate) holds 3 - k high columns of 5: f = 0.4
    at k = 1 (not lit), f = 0.2 at k = 2 (lit), 0 beyond. So within rows and columns clear of the
    other edges, the leak is the column i_h + 2 exactly, and it is a leak (30 texels inside the
    exact shadow the low plate casts), not the shadow's edge."""
    import dsm.pipeline as pl
    from dsm.truth import metrics
    from dsm.core.types import MomentSpec
    from dsm.prefilter import vsm
    sd = pl.load_scene(pl.scene_spec({"builtin": "stacked_plates"}), (160, 160))
    setup = pl.light_setup(sd, pl.gbuffer(sd), sd.own_lights[0], "sun")
    R = 256
    view = pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    rx = pl.receivers(view, setup, sd.diagonal)
    spec = MomentSpec("vsm", vsm.Params(min_variance=1e-4), 5)
    v, _ = pl.moment_visibility(spec, rx, pl.moment_map(spec, smap, "float32"), smap)
    v = v.numpy()
    col, row = np.floor(rx.u_map.numpy()), np.floor(rx.v_map.numpy())
    u0, u1 = (float(view.project(mi.Point3f(x, 0.0, 0.0))[0].numpy()[0]) for x in (0.0, 0.75))   # plate edges
    v_lo, v_hi = sorted(float(view.project(mi.Point3f(0.0, y, 0.0))[1].numpy()[0]) for y in (-0.75, 0.75))
    assert u1 > u0                                          # u grows with world x (the light frame)
    i_h = np.ceil(u0 - 0.5) - 1                             # centre (i + 0.5) < u0: the high plate's
    ground = setup.shape == sd.shape_names.index("ground")
    region = ground & ~setup.v_star & (col > i_h) & (col < np.floor(u1) - 3) & (row > v_lo + 3) & (row < v_hi - 3)
    assert region.sum() > 30 and (col[region] == i_h + 2).sum() > 3
    lit = v >= 0.5
    assert (lit[region] == (col[region] == i_h + 2)).all()
    deep = pl.deep_in_shadow(sd, setup, rx.texel_world.numpy(), 2.0)
    assert deep[region].all()                   # the ground under the low plate, 30 texels from its edges
    split = metrics.leak_split(v[region], setup.v_star[region], deep[region])
    assert split["n_leak"] == (col[region] == i_h + 2).sum() and split["n_peterpan_edge"] == 0


def _plates_region(low: float, high: float, R: int = 256):
    """stacked_plates at ``low`` and ``high``, light straight down: (scene, set-up, view, map,
    receivers, column, i_h, ground under the low plate alone clear of its other edges)."""
    import dsm.pipeline as pl
    sd = pl.load_scene(pl.scene_spec({"builtin": "stacked_plates", "low": low, "high": high}), (160, 160))
    setup = pl.light_setup(sd, pl.gbuffer(sd), sd.own_lights[0], "sun")
    view = pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    rx = pl.receivers(view, setup, sd.diagonal)
    col, row = np.floor(rx.u_map.numpy()), np.floor(rx.v_map.numpy())
    u0, u1 = (float(view.project(mi.Point3f(x, 0.0, 0.0))[0].numpy()[0]) for x in (0.0, 0.75))
    v_lo, v_hi = sorted(float(view.project(mi.Point3f(0.0, y, 0.0))[1].numpy()[0]) for y in (-0.75, 0.75))
    i_h = np.ceil(u0 - 0.5) - 1
    ground = setup.shape == sd.shape_names.index("ground")
    region = ground & ~setup.v_star & (col > i_h) & (col < np.floor(u1) - 6) & (row > v_lo + 6) & (row < v_hi - 6)
    return sd, setup, smap, rx, col, i_h, region


def chebyshev_band(low: float, high: float):
    """The window fractions f of high-plate texels that light a ground receiver under the low plate
    alone: Chebyshev's bound with two depths z1 < z2 (D = z2 - z1) and the receiver g behind z2 is
    V = f(1-f) D^2 / (f(1-f) D^2 + (g + f D)^2) >= 0.5 exactly when 2 f^2 - (1 - 2r) f + r^2 <= 0,
    r = g / D (the depth normalization cancels); (f_lo, f_hi), or None where it has no solution
    (D / g < 2 + 2 sqrt 2)."""
    r = low / (high - low)
    disc = (1 - 2 * r) ** 2 - 8 * r * r
    if disc < 0:
        return None
    return ((1 - 2 * r) - np.sqrt(disc)) / 4, ((1 - 2 * r) + np.sqrt(disc)) / 4


@pytest.mark.slow
@pytest.mark.parametrize("low, high, W", [(0.25, 2.0, 5), (0.25, 2.0, 9), (0.1, 2.0, 15), (1.0, 2.0, 9),
                                          (0.5, 2.0, 9)])
def test_the_vsm_leak_is_chebyshevs_band_and_nothing_where_the_band_has_no_solution(low, high, W):
    """The ground receivers under the low plate alone that VSM lights and the probes find deep in
    the exact shadow: their columns are those whose W-window holds a fraction f_j = ((W+1)/2 - j)/W
    of high-plate columns (column i_h + j) inside the derived band, to within one column at either
    edge; where the band has no solution (D / g = 1 and 3 here) no receiver leaks."""
    import dsm.pipeline as pl
    from dsm.core.types import MomentSpec
    from dsm.prefilter import vsm
    from dsm.truth import metrics
    sd, setup, smap, rx, col, i_h, region = _plates_region(low, high)
    spec = MomentSpec("vsm", vsm.Params(min_variance=1e-4), W)
    v, _ = pl.moment_visibility(spec, rx, pl.moment_map(spec, smap, "float32"), smap)
    deep = pl.deep_in_shadow(sd, setup, rx.texel_world.numpy(), 2.0)
    leak = metrics.leak_mask(v.numpy(), setup.v_star, deep)
    assert region.sum() > 100 and deep[region].all()
    got = sorted({int(c - i_h) for c in col[region & leak]})
    band = chebyshev_band(low, high)
    if band is None:
        assert got == [] and high / low - 1 < 2 + 2 * np.sqrt(2)
        return
    want = [j for j in range(1, (W + 1) // 2 + 1) if band[0] <= ((W + 1) / 2 - j) / W <= band[1]]
    assert want and got, (band, want, got)
    assert abs(got[0] - want[0]) <= 1 and abs(got[-1] - want[-1]) <= 1, (band, want, got)


@pytest.mark.parametrize("kind, params", [("esm", {}), ("evsm", {}), ("msm", {})])
def test_esm_evsm_and_msm_do_not_leak_where_vsm_does(kind, params):
    """The same two occluders (D / g = 7, VSM's band f in [0.031, 0.326]): ESM's bound
    (f e^(c z1) + (1 - f) e^(c z2)) e^(-c t) <= e^(-c g) is below 0.5 once c g > ln 2 (c = 80, g
    about 0.1 normalized: 8); EVSM's warp e^(c z) stretches g against D (r = g_w / D_w >> 1, no
    solution); MSM's four moments hold both depths, both in front of the receiver (V 0 up to its
    moment bias). None of the three lights a receiver deep in this shadow."""
    import dsm.pipeline as pl
    from dsm.core.types import MomentSpec
    from dsm.prefilter import get
    from dsm.truth import metrics
    sd, setup, smap, rx, col, i_h, region = _plates_region(0.25, 2.0)
    spec = MomentSpec(kind, get(kind).Params(**params), 9)
    v, _ = pl.moment_visibility(spec, rx, pl.moment_map(spec, smap, "float32"), smap)
    deep = pl.deep_in_shadow(sd, setup, rx.texel_world.numpy(), 2.0)
    leak = metrics.leak_mask(v.numpy(), setup.v_star, deep)
    assert region.sum() > 100 and not leak[region].any()


@pytest.mark.slow
def test_an_outline_error_of_a_depth_map_is_never_a_leak(run_dict):
    """Schemes without bias and with biases below the occluders' gaps (0.2 and 0.25 world), nearest
    and PCF, on the plates (whose high plate's shadow outline runs along the low plate's own edge)
    and the floating plate (its occluder far above the ground: the old distance-to-occluder split
    called every outline error there a leak): a depth map's peter-panning is at the shadow's edge,
    never leak. A bias beyond the gap (0.3) lights the ground deep inside the shadow: that is leak."""
    res = run_dict(base_config(scene=[{"builtin": "stacked_plates"}, {"builtin": "floating_plate"}],
                               camera={"resolution": [64, 64]},
                               map={"resolution": [64, 256], "kind": ["depth"], "filter": ["nearest", "pcf_bilinear"]},
                               scheme=[{"name": "constant", "bias": [0.0, 0.1, 0.3]}, {"name": "normal_offset"},
                                       {"name": "receiver_plane"}, {"name": "slope_scaled"}]))
    within = [r for r in res.rows if r["params"] != "bias=0.3"]
    assert sum(r["n_peterpan"] for r in within) > 20          # outline errors there are, and none leaks
    assert all(r["n_leak"] == 0 and r["n_peterpan_edge"] == r["n_peterpan"] for r in within)
    beyond = [r for r in res.rows if r["params"] == "bias=0.3" and r["resolution"] == 256]
    assert all(r["n_leak"] > 0 for r in beyond)


def test_msm_where_float32_leaves_the_system_singular_falls_back_to_chebyshev():
    """A window of one depth (0.8347) under the default bias 3e-5, the receiver 2.5e-5 behind
    it: float32's Cholesky gives c2 = 0 and a NaN bound (found in l_shape at W = 9). V is then
    Chebyshev's bound of the biased E[t], E[t^2], computed here in float64."""
    from dsm.prefilter import msm
    b = [0.83470887, 0.6967454, 0.5815904, 0.48547226]
    t, a = 0.83473355, 3e-5
    v = _np(msm.visibility([_f([x]) for x in b], _f([t]), _prm(moment_bias=a, depth_bias=0.0)))[0]
    b0, b1 = ((1 - a) * np.float32(x).astype(np.float64) + a * 0.5 for x in b[:2])
    var = b1 - b0 * b0
    t64 = float(np.float32(t))
    want = 1.0 if t64 <= b0 else var / (var + (t64 - b0) ** 2)
    assert np.isfinite(v) and v == pytest.approx(want, abs=0.05)


@pytest.mark.parametrize("b, t, a", [
    # d33d22 = 0 in float32: c2 = -inf and the roots NaN; the receiver far behind the one caster
    ([9.109666e-05, 8.298602e-09, 7.559749e-13, 6.8866796e-17], 0.14421274, 3e-5),
    # no moment bias: d22 = 0 in float32
    ([0.4790513, 0.22949015, 0.10993756, 0.05266573], 0.62705207, 0.0)])
def test_msm_whose_roots_are_nan_falls_back_to_chebyshev_not_to_lit(b, t, a):
    """Windows of one depth where float32 leaves the Hankel system singular and the roots NaN (found
    among random windows): the bound is Chebyshev's of the biased E[t], E[t^2] (float64 here), as where
    c2 = 0, not V = 1 (a NaN root compared false on both sides and the shadow summed to 0: lit)."""
    from dsm.prefilter import msm
    v = _np(msm.visibility([_f([x]) for x in b], _f([t]), _prm(moment_bias=a, depth_bias=0.0)))[0]
    b0, b1 = ((1 - a) * np.float32(x).astype(np.float64) + a * 0.5 for x in b[:2])
    var, t64 = max(b1 - b0 * b0, 0.0), float(np.float32(t))
    want = var / (var + (t64 - b0) ** 2)
    assert t64 > b0 and v == pytest.approx(want, abs=1e-3) and v < 0.01


def _forward(f, x):
    """(f(x), df/dx) per element by Dr.Jit's forward mode, numpy float64."""
    x = _f(x)
    dr.enable_grad(x)
    y = f(x)
    dr.forward(x)
    return _np(dr.detach(y)), _np(dr.grad(y))


def _backward(f, x):
    """(f(x), df/dx) per element by Dr.Jit's reverse mode (f elementwise), numpy float64: a select's
    unused branch gets a zero adjoint, which an unguarded inf turns into NaN (forward mode does not)."""
    x = _f(x)
    dr.enable_grad(x)
    y = f(x)
    dr.backward(y)
    return _np(dr.detach(y)), _np(dr.grad(x))


def test_chebyshevs_derivative_holds_at_evsms_warped_variance():
    """EVSM's warped moments reach e^80: var / (var + d^2)'s derivative squares e^80 (inf in float32,
    NaN gradients for dsm grad). The bound's derivative in t is its stable form's, -2 d var / (var +
    d^2)^2 computed in float64, and its value the quotient's to the bit with or without AD."""
    from dsm.prefilter.base import chebyshev
    c = 40.0
    mean = np.exp(c * RNG.uniform(-0.5, 0.9, 500))
    var = mean * mean * RNG.uniform(0.01, 0.5, 500)
    t = mean * RNG.uniform(1.05, 3.0, 500)
    args = [_f(mean), _f(mean * mean + var)]
    v, dv = _forward(lambda x: chebyshev(*args, x, 1e-4), t)
    plain = _np(chebyshev(*args, _f(t), 1e-4))
    assert np.array_equal(v, plain) and np.isfinite(dv).all()
    m32, s32, t32 = (np.float32(a_).astype(np.float64) for a_ in (mean, mean * mean + var, t))
    var64 = np.maximum(s32 - m32 * m32, 1e-4)
    d = t32 - m32
    want = -2.0 * d * var64 / (var64 + d * d) ** 2
    assert np.allclose(dv, want, rtol=2e-3, atol=0.0)


def test_msms_derivative_is_finite_where_its_system_is_singular():
    """Reverse mode through the guarded lookup (dsm grad's moments are attached): over windows of one
    depth (blur 1: every texel of an unfiltered map) under the default bias, where float32's system is
    often singular, the derivative in the caster's depth is finite; in t, on three-caster windows, it is
    the float64 central difference of the numpy reference (median gap under 5 %)."""
    from dsm.prefilter import msm
    prm = _prm(moment_bias=3e-5, depth_bias=0.0)
    z, t = RNG.uniform(0.05, 0.95, 2000), _f(RNG.uniform(0.0, 1.0, 2000))
    _, dv = _backward(lambda x: msm.visibility([x ** k for k in (1, 2, 3, 4)], t, prm), z)   # the caster moves
    assert np.isfinite(dv).all()
    zz = RNG.uniform(0.1, 0.9, (3, 200))
    w = RNG.dirichlet([1, 1, 1], 200).T
    b = np.float32(np.stack([(w * zz ** k).sum(0) for k in (1, 2, 3, 4)])).astype(np.float64)
    t = np.float32(RNG.uniform(0.1, 0.9, 200)).astype(np.float64)
    alpha, h = 2e-3, 1e-4
    v, dv = _backward(lambda x: msm.visibility([_f(x_) for x_ in b], x, _prm(moment_bias=alpha, depth_bias=0.0)), t)
    fd = (_hamburger_np(b, t + h, alpha) - _hamburger_np(b, t - h, alpha)) / (2 * h)
    assert np.isfinite(dv).all() and np.median(np.abs(dv - fd)) < 0.05 * np.median(np.abs(fd))


def test_dsm_schemes_lists_each_map_kind_with_its_source_and_parameters():
    from dataclasses import fields
    from dsm import prefilter
    from dsm.cli import schemes_text
    text = schemes_text()
    for k in prefilter.REGISTRY:
        assert f"{k.NAME}  [{k.SOURCE}]" in text
        for f in fields(k.Params):
            assert f"    {f.name} = {f.default}" in text


@pytest.mark.slow
def test_a_resumed_run_keeps_its_moment_cases(run_dict, tmp_path):
    import dsm
    cfg = base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [32, 32]},
                      map={"resolution": 32, "kind": ["depth", "vsm", "msm"], "blur": [1, 3]})
    first = dsm.run(cfg, out=tmp_path / "r", report=False)
    again = dsm.run(cfg, out=tmp_path / "r", resume=True, report=False)
    assert again.run["resumed_cases"] == len(first.rows) == 1 + 2 * 2
    assert [(r["case"], r["scheme"], r["filter"], r["n_leak"]) for r in again.rows] == \
        [(r["case"], r["scheme"], r["filter"], r["n_leak"]) for r in first.rows]


def test_mjp_presets_are_mjps_defaults_in_the_kits_units():
    """MJP's Shadows sample: AppSettings.cs VSMBias = 0.01 (used as VSMBias * 0.01), MSMMomentBias
    = 0.003 (used x 0.001), exponents 40 / 5. Its EVSM minimum variance is (VSMBias * 0.01 * c w)^2
    in x = 2t - 1; the kit's EVSM with the preset's min_variance must give the same V as MJP's
    ChebyshevUpperBound with that variance, written here in float64."""
    from dsm.config import read as config
    from dsm.prefilter import evsm
    cfg = config.parse(base_config(map={"kind": ["depth", "vsm", "evsm", "msm"], "vsm": {"preset": "mjp"},
                                        "evsm": {"preset": "mjp"}, "msm": {"preset": "mjp"}}), "<test>")
    got = {m.name: m for m in cfg.map.moments}
    assert got["vsm"].params.min_variance == pytest.approx(0.01 * 0.01) and got["vsm"].params.bleed == 0.0
    assert got["msm"].params.moment_bias == pytest.approx(0.003 * 0.001) and got["msm"].preset == "mjp"
    p = got["evsm"].params
    assert (p.positive, p.negative, p.moments) == (40.0, 5.0, 4)
    # MJP's EVSM4 in float64 on the moments of a two-caster window
    za, zb, f = RNG.uniform(0.2, 0.5, 200), RNG.uniform(0.5, 0.8, 200), RNG.uniform(0, 1, 200)
    moms = [f * a + (1 - f) * b_ for a, b_ in zip(evsm.moments(za, p), evsm.moments(zb, p))]
    t = np.float32(RNG.uniform(0.3, 0.9, 200)).astype(np.float64)
    x = 2 * t - 1
    w = np.stack([np.exp(40 * x), -np.exp(-5 * x)])
    min_var = (0.01 * 0.01 * np.array([[40.0], [5.0]]) * w) ** 2
    m32 = [np.float32(m).astype(np.float64) for m in moms]

    def cheb(m1, m2, d, mv):        # MJP's ChebyshevUpperBound, bleed 0
        var = np.maximum(m2 - m1 * m1, mv)
        return np.where(d <= m1, 1.0, var / (var + (d - m1) ** 2))
    want = np.minimum(cheb(m32[0], m32[1], w[0], min_var[0]), cheb(m32[2], m32[3], w[1], min_var[1]))
    v = _np(evsm.visibility([_f(m) for m in moms], _f(t), _prm(positive=40, negative=5, min_variance=p.min_variance,
                                                                bleed=0.0)))
    assert np.abs(v - want).max() < 2e-3 and (want < 0.5).any() and (want > 0.5).any()


def _preset(kind, name):
    from dsm.config import read as config
    cfg = config.parse(base_config(map={"kind": ["depth", kind], kind: {"preset": name}}), "<test>")
    (spec,) = cfg.map.moments
    return spec.params


def _two_caster_moments(moments_of, p, n=400):
    """The moments of windows covering two casters, a share f at za and 1 - f at zb."""
    za, zb, f = RNG.uniform(0.2, 0.5, n), RNG.uniform(0.5, 0.8, n), RNG.uniform(0, 1, n)
    return [f * a + (1 - f) * b_ for a, b_ in zip(moments_of(za, p), moments_of(zb, p))]


def test_three_js_preset_is_three_js_vsm_shadow_in_float64():
    """three.js's VSMShadow (shadowmap_pars_fragment.glsl.js): the map holds the mean and standard
    deviation; variance = std^2 floored at 0, p = var / (var + d^2), clamp((p - 0.3) / (0.95 -
    0.3)), lit where the compared depth is at or before the mean. Written here in float64 from
    the mean and standard deviation, against the kit's VSM with the preset."""
    from dsm.prefilter import vsm
    p = _preset("vsm", "three")
    moms = _two_caster_moments(vsm.moments, p)
    m1, m2 = (np.float32(m).astype(np.float64) for m in moms)
    t = np.float32(RNG.uniform(0.15, 0.9, len(m1))).astype(np.float64)
    std = np.sqrt(np.maximum(m2 - m1 * m1, 0.0))
    var = np.maximum(0.0, std * std)
    d = t - m1
    soft = np.clip((var / (var + d * d) - 0.3) / (0.95 - 0.3), 0.0, 1.0)
    want = np.where(t <= m1, 1.0, soft)
    v = _np(vsm.visibility([_f(m) for m in moms], _f(t), _prm(**vars(p))))
    big = var > 1e-4          # where float32's E[t^2] - E[t]^2 keeps 3 digits of the variance
    assert np.abs(v - want)[big].max() < 2e-3 and (want < 0.5).any() and (want > 0.5).any()
    assert ((v < 0.5) == (want < 0.5))[np.abs(want - 0.5) > 0.05].all()


@pytest.mark.parametrize("name, elvsm", [("filament", False), ("filament_elvsm", True)])
def test_filament_presets_are_filaments_shadow_sample_vsm_in_float64(name, elvsm):
    """Filament's ShadowSample_VSM (shadowing.fs) with prepareShadowVSM's uniforms: exponent 5.54,
    vsmDepthScale = minVarianceScale 0.5 * 0.01 * 5.54, each warp's variance floored at
    (vsmDepthScale w)^2, reduceLightBleed(p, 0.15) = linstep(0.15, 1, p); with elvsm the smaller of
    the positive warp's bound and the negative warp's (-1/w). Written in float64 from those
    constants, against the kit's EVSM with the preset."""
    from dsm.prefilter import evsm
    p = _preset("evsm", name)
    assert (p.moments == 4) == elvsm
    moms = _two_caster_moments(evsm.moments, p)
    m32 = [np.float32(m).astype(np.float64) for m in moms]
    t = np.float32(RNG.uniform(0.15, 0.9, len(m32[0]))).astype(np.float64)
    c, depth_scale, amount = 5.54, 0.5 * 0.01 * 5.54, 0.15

    def evaluate(m1, m2, w):
        var = np.maximum(m2 - m1 * m1, (depth_scale * w) ** 2)
        bound = np.clip((var / (var + (w - m1) ** 2) - amount) / (1 - amount), 0.0, 1.0)
        return np.where(w <= m1, 1.0, bound)
    w = np.exp(c * (2 * t - 1))
    want = evaluate(m32[0], m32[1], w)
    if elvsm:
        want = np.minimum(want, evaluate(m32[2], m32[3], -1.0 / w))
    v = _np(evsm.visibility([_f(m) for m in moms], _f(t), _prm(**vars(p))))
    assert np.abs(v - want).max() < 2e-3 and (want < 0.5).any() and (want > 0.5).any()


def test_vsm_bleed_high_above_bleed_and_the_old_label_kept():
    """bleed_high at or below bleed is refused naming the key; a VSM instance that leaves it at 1
    keeps the label earlier runs wrote (no bleed_high word)."""
    from dsm.config import read as config
    from dsm.prefilter import vsm
    with pytest.raises(config.ConfigError) as e:
        config.parse(base_config(map={"kind": ["depth", "vsm"], "vsm": {"bleed": 0.4, "bleed_high": 0.4}}), "<test>")
    assert e.value.key == "map.vsm.bleed_high"
    from dsm.core.types import describe_params
    assert "bleed_high" not in describe_params(vsm.Params()) and "bleed_high=0.95" in describe_params(
        _preset("vsm", "three"))


def test_dsm_schemes_names_the_engine_files_of_the_pre_filtered_presets():
    from dsm.cli import schemes_text
    text = schemes_text()
    for needle in ("vsm three:", "evsm filament:", "evsm filament_elvsm:", "shadowmap_pars_fragment.glsl.js",
                   "shaders/src/shadowing.fs", "VsmShadowOptions", "TheRealMJP/Shadows"):
        assert needle in text, needle


def test_a_preset_takes_no_other_keys_and_esm_has_none():
    from dsm.config import read as config
    for m, key in (({"kind": "vsm", "vsm": {"preset": "mjp", "bleed": 0.1}}, "map.vsm.bleed"),
                   ({"kind": "esm", "esm": {"preset": "mjp"}}, "map.esm.preset"),
                   ({"kind": "msm", "msm": {"preset": "three"}}, "map.msm.preset")):
        with pytest.raises(config.ConfigError) as e:
            config.parse({"scene": [{"builtin": "plane"}], "map": m}, "<test>")
        assert e.value.key == key


def test_a_list_of_presets_sweeps_them_and_default_is_the_kinds_defaults():
    """``preset = ["default", "three", "mjp"]``: one instance each, in that order, with the values of
    prefilter.presets (and of a table without keys for "default")."""
    from dsm import prefilter
    from dsm.config import read as config
    cfg = config.parse(base_config(map={"kind": ["depth", "vsm"], "vsm": {"preset": ["default", "three", "mjp"]},
                                        "blur": [1, 5]}), "<test>")
    plain = config.parse(base_config(map={"kind": ["depth", "vsm"], "blur": [1, 5]}), "<test>")
    got = [(s.preset, s.params, s.blur) for s in cfg.map.moments]
    want = [(None, plain.map.moments[0].params, 1), (None, plain.map.moments[0].params, 5),
            ("three", prefilter.presets.PRESETS["vsm"]["three"], 1), ("three", prefilter.presets.PRESETS["vsm"]["three"], 5),
            ("mjp", prefilter.presets.PRESETS["vsm"]["mjp"], 1), ("mjp", prefilter.presets.PRESETS["vsm"]["mjp"], 5)]
    assert got == want
    for bad in ([], ["three", "unreal"]):
        with pytest.raises(config.ConfigError) as e:
            config.parse(base_config(map={"kind": ["depth", "vsm"], "vsm": {"preset": bad}}), "<test>")
        assert e.value.key == "map.vsm.preset" and "default" in e.value.choices


def test_the_summary_pools_the_leak_split_per_instance():
    from dsm.report import summary
    base = {"preset": "", "format": "float32", "cascade_layout": ""}
    rows = [{**base, "scheme": "vsm", "params": "min_variance=0.0001", "filter": "box:3", "map_kind": "vsm",
             "n_gt_shadowed": 100, "n_peterpan": 10, "n_peterpan_edge": 4, "n_leak": 6, "mean_abs_error": 0.02,
             "moments_ms": 3.0},
            {**base, "scheme": "vsm", "params": "min_variance=0.0001", "filter": "box:3", "map_kind": "vsm",
             "n_gt_shadowed": 300, "n_peterpan": 2, "n_peterpan_edge": 2, "n_leak": 0, "mean_abs_error": 0.04,
             "moments_ms": 5.0},
            {**base, "scheme": "constant", "params": "bias=1 texel", "filter": "nearest", "map_kind": "depth",
             "n_gt_shadowed": 50, "n_peterpan": 1, "n_peterpan_edge": 1, "n_leak": 0, "mean_abs_error": 0.01,
             "moments_ms": float("nan")}]
    lines = summary.leak_md(rows)
    # vsm: leak 6 / 400 = 0.015, contact 6 / 400, peter-pan 12 / 400 = 0.03, mae (0.02 + 0.04) / 2, moments 4 ms
    assert "| vsm | min_variance=0.0001 | box:3 | vsm | 2 | 0.03 | 0.015 | 0.015 | 0.03 | 4.00 |" in lines
    assert "| constant | bias=1 texel | nearest | depth | 1 | 0.02 | 0.02 | 0 | 0.01 | - |" in lines
    assert lines.index("| constant | bias=1 texel | nearest | depth | 1 | 0.02 | 0.02 | 0 | 0.01 | - |") < \
        lines.index("| vsm | min_variance=0.0001 | box:3 | vsm | 2 | 0.03 | 0.015 | 0.015 | 0.03 | 4.00 |")
    assert summary.leak_md([{k: v for k, v in r.items() if k != "map_kind"} for r in rows]) == []


@pytest.mark.parametrize("extra,key", [
    ({"light": [{"type": "area", "shape": "rectangle", "position": [0, 0, 3], "direction": [0, 0, -1],
                 "size": 1.0}]}, "map.kind"),
    ({"map": {"kind": "vsm", "moment_samples": 2}, "motion": [{"frames": 3, "camera": "dolly", "offset": [0, 1, 0]}]},
     "map.moment_samples"),
    ({"map": {"kind": "vsm", "mipmaps": True}, "motion": [{"frames": 3, "camera": "dolly", "offset": [0, 1, 0]}]},
     "map.mipmaps"),
], ids=["area light", "motion supersampled", "motion mipmapped"])
def test_pre_filtered_kinds_refuse_area_lights_and_what_motion_cannot_rebuild(extra, key):
    from dsm.config import read as config
    with pytest.raises(config.ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane"}], "map": {"kind": "vsm"}, **extra}, "<test>")
    assert e.value.key == key


@pytest.mark.slow
def test_motion_of_a_pre_filtered_map_frame_by_frame_equals_still_runs_at_each_camera(run_dict):
    """[[motion]] with [map] kind: each frame's moments are built from that frame's map (re-fitted to
    the frame's receivers), so a frame's counts (frames.csv) equal those of a still run (the runner's
    path: a second computation) with the camera where the frame puts it; the case's counts are the
    frames' sums."""
    import csv
    import math
    import mitsuba as mi
    from dsm.maps.cascades import Camera
    from dsm.scenes.camera import look_at_sensor
    poses = [([2.0, -2.5, 2.2], [0.0, 0.0, 0.2]), ([2.6, -1.5, 2.0], [0.2, 0.1, 0.0])]
    mp = {"resolution": 128, "kind": ["depth", "vsm", "evsm"], "blur": [1, 3]}
    common = dict(scene=[{"builtin": "floating_plate"}], map=mp, scheme=[{"name": "constant"}])
    clips = {"near": 0.01, "far": 100.0}
    keys = [{"position": p, "target": t} for p, t in poses]
    moved = run_dict(base_config(camera={"resolution": [40, 40], "position": poses[0][0], "target": poses[0][1],
                                         "fov": 50, **clips}, **common,
                                 motion=[{"frames": 2, "camera": "keyframes", "keys": keys, "points": 400}]), "moved")
    with open(moved.out / "frames.csv", newline="") as fh:
        frames = list(csv.DictReader(fh))
    label = lambda r: (r["scheme"], r["filter"])
    assert sorted({label(r) for r in moved.rows}) == sorted([("constant", "nearest"), ("vsm", "box:1"),
                                                             ("vsm", "box:3"), ("evsm", "box:1"), ("evsm", "box:3")])
    # the frames' sensors keep frame 0's film, fov, clips and (orthonormalized) up: the still runs too
    base = Camera.from_sensor(mi.load_dict(look_at_sensor(*poses[0], [0, 0, 1], 50, 40, 40, **clips)))
    fov, up = math.degrees(2 * math.atan(base.tan_x)), [float(c) for c in base.up]
    for t, (pos, tgt) in enumerate(poses):
        cam = {"resolution": [40, 40], "position": pos, "target": tgt, "fov": fov, "up": up, **clips}
        still = run_dict(base_config(camera=cam, **common), f"still{t}")
        at_t = {label(f): f for f in frames if int(f["frame"]) == t}
        for r in still.rows:
            f = at_t[label(r)]
            assert int(f["n_receivers"]) == r["n_receivers"] > 100, (t, label(r))
            n_wrong = round(float(f["error_rate"]) * r["n_receivers"])    # frames.csv holds 6 digits
            assert n_wrong == r["n_acne"] + r["n_peterpan"], (t, label(r))
    for r in moved.rows:
        n = sum(int(f["n_receivers"]) for f in frames if label(f) == label(r))
        assert r["n_receivers"] == n and r["map_kind"] == ("depth" if r["scheme"] == "constant" else r["scheme"])
        assert r["n_leak"] <= r["n_peterpan"]


@pytest.mark.slow
def test_the_error_image_paints_the_leaks_in_their_own_colour(run_dict):
    """With the leak split, each leaking receiver (peter-panned at least leak_texels inside the
    exact shadow) is the LEAK class, one pixel per n_leak, written in LEAK's colour; folded back it is
    peter-panning, so the image counts stay those of metrics.csv."""
    from PIL import Image
    from dsm.report import figures
    from dsm.truth import metrics
    res = run_dict(base_config(scene=[{"builtin": "stacked_plates"}], camera={"resolution": [48, 48]},
                               map={"resolution": 64, "kind": ["depth", "vsm"], "blur": [5]}))
    (vsm5,) = [r for r in res.rows if r["scheme"] == "vsm"]
    img = res.images[vsm5["case"]]
    assert vsm5["n_leak"] > 0 and (img == metrics.LEAK).sum() == vsm5["n_leak"]
    assert (metrics.base_class(img) == metrics.PETERPAN).sum() == vsm5["n_peterpan"]
    png = np.asarray(Image.open(res.out / "images" / figures.image_folder(vsm5) / f"{vsm5['case']}_error.png").convert("RGB"))
    assert (png[img == metrics.LEAK] == metrics.CLASS_COLORS[metrics.LEAK]).all()


def test_supersampled_moments_are_the_mean_of_each_texel_s_analytic_samples():
    """``[map] moment_samples = N``: a texel's E[t] is the mean of the normalized depths of N x N
    rays at its sub-texel centres. On stacked_plates (light straight down) each sample's first hit
    is the highest of the ground (z 0 over |x|, |y| <= 4; beyond it a miss, t = 1), the low plate (z 0.25 over |x|, |y| <= 0.75) and the high
    plate (z 2 over -0.75 <= x <= 0, |y| <= 0.75): the expected mean computed in numpy float64 from
    the view's frame, away from the samples that sit on an edge."""
    import numpy as np
    import dsm.pipeline as pl
    from dsm.config import read as config
    cfg = pl.prepare(config.parse(base_config(scene=[{"builtin": "stacked_plates"}], map={
        "resolution": 32, "kind": ["vsm"], "moment_samples": [1, 4]}, scheme=[]), "<test>"))
    sd = pl.load_scene(cfg.scenes[0], (48, 48))
    light = sd.lights_for(cfg.lights)[0]
    view = pl.make_view(light, 32, np.zeros((0, 3)), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    one, four = cfg.map.moments
    assert (one.samples, four.samples, four.filter) == (1, 4, "box:1/ss4")
    fine = pl.supersampled_map(sd.scene, view, 4)
    got = pl.moment_map(four, smap, "float32", fine).b[0].numpy().reshape(32, 32)
    N, R, w = 4, 32, view.extent / 32
    sub = (np.arange(R * N) + 0.5) / N * w                 # sample positions along ex, ey (world, from the origin)
    ex, ey, ez = view.axes_np
    p = view.origin_np + sub[None, :, None] * ex + sub[:, None, None] * ey      # [row (ey), column (ex), xyz]
    x, y = p[..., 0], p[..., 1]
    low = (np.abs(x) <= 0.75) & (np.abs(y) <= 0.75)
    high = (x >= -0.75) & (x <= 0.0) & (np.abs(y) <= 0.75)
    z = np.where(high, 2.0, np.where(low, 0.25, 0.0))
    hit = np.concatenate([p[..., :2], z[..., None]], axis=-1)     # straight down to the highest surface
    depth = (hit - view.origin_np) @ ez
    ground = (np.abs(x) <= 4.0) & (np.abs(y) <= 4.0)                   # beyond it a ray misses: t = 1
    t = np.where(ground | low, (depth - view.near) / (view.far - view.near), 1.0)
    want = t.reshape(R, N, R, N).mean(axis=(1, 3))
    edge = np.minimum.reduce([np.abs(np.abs(x) - 0.75), np.abs(np.abs(y) - 0.75), np.abs(x),
                              np.abs(np.abs(x) - 4.0), np.abs(np.abs(y) - 4.0)]) < 1e-4
    clean = ~edge.reshape(R, N, R, N).any(axis=(1, 3))
    mixed = clean & (t.reshape(R, N, R, N).std(axis=(1, 3)) > 0)       # texels whose samples see two heights
    assert mixed.sum() >= 10
    np.testing.assert_allclose(got[clean], want[clean], atol=2e-6)
    single = pl.moment_map(one, smap, "float32").b[0].numpy().reshape(32, 32)
    assert np.abs(single[mixed] - want[mixed]).max() > 0.01      # one ray a texel sees one height of the mix


def test_the_mip_chain_is_each_face_s_two_by_two_means_down_to_one_texel():
    """Sides 12 -> 6 -> 3 -> 2 (3 padded by its edge texel) -> 1, computed texel by texel in float64."""
    import numpy as np
    from dsm.prefilter import mipmaps
    x = np.random.default_rng(5).random(2 * 12 * 12)
    levels = mipmaps.chain(x, 2, 12, lambda v: v)
    assert [r for r, _ in levels] == [6, 3, 2, 1]
    img = x.reshape(2, 12, 12)
    for r, vals in levels:
        n = img.shape[1]
        pad = np.pad(img, ((0, 0), (0, n % 2), (0, n % 2)), mode="edge")
        want = np.array([[[pad[f, 2 * j:2 * j + 2, 2 * i:2 * i + 2].mean() for i in range(r)] for j in range(r)]
                         for f in range(2)])
        np.testing.assert_allclose(vals.reshape(2, r, r), want, rtol=0, atol=1e-15)
        img = want


def test_a_mipmapped_vsm_reads_the_level_of_each_receiver_s_pixel_footprint():
    """V of a mipmapped VSM against numpy float64: lambda = log2 of the footprint in texels from the
    camera's pixel area (dsm.scenes.camera.Camera.pixel_area, a second computation), the two
    levels' nearest texels (means of the map's 2^l x 2^l blocks) mixed by frac(lambda), then
    Chebyshev's bound; and without a camera the map itself."""
    import dataclasses
    import numpy as np
    import dsm.pipeline as pl
    from dsm.config import read as config
    from dsm.prefilter import mipmaps
    cfg = pl.prepare(config.parse(base_config(scene=[{"builtin": "stacked_plates"}], map={
        "resolution": 64, "kind": ["vsm"], "mipmaps": True}, scheme=[]), "<test>"))
    sd = pl.load_scene(cfg.scenes[0], (24, 24))
    gb = pl.gbuffer(sd)
    light = sd.lights_for(cfg.lights)[0]
    setup = pl.light_setup(sd, gb, light, "sun")
    view = pl.make_view(light, 64, pl.points_np(setup.p), sd.bbox)
    rx = pl.receivers(view, setup, sd.diagonal)
    (spec,) = cfg.map.moments
    assert spec.filter == "box:1/mip"
    mm = pl.moment_map(spec, pl.build_map(sd.scene, view), "float32")
    got = pl.moment_visibility(spec, rx, mm, pl.build_map(sd.scene, view))[0].numpy()
    p, n = pl.points_np(rx.p_world), pl.points_np(rx.n_world)
    area = setup.camera.pixel_area(p, n) * np.abs((n * pl.points_np(rx.to_light)).sum(1))
    lam = np.clip(0.5 * np.log2(np.maximum(area / rx.texel_world.numpy().astype(float) ** 2, 1.0)), 0, 6)
    assert (lam > 1).mean() > 0.2                      # the camera is coarse: many receivers minify
    b = [np.asarray(m.numpy(), float).reshape(64, 64) for m in mm.b]
    levels = [b] + [[v.reshape(r, r) for v in vals] for vals, r in
                    zip(zip(*[[v for _, v in mipmaps.chain(m.reshape(-1), 1, 64, lambda x: x.astype(np.float32))]
                              for m in b]), [32, 16, 8, 4, 2, 1])]
    u, v = rx.u_map.numpy(), rx.v_map.numpy()

    def at(level):
        side = 64 >> level
        i = np.clip(np.floor(u / 2 ** level).astype(int), 0, side - 1)
        j = np.clip(np.floor(v / 2 ** level).astype(int), 0, side - 1)
        return [m[j, i] for m in levels[level]]
    l0 = np.floor(lam).astype(int)
    f = lam - l0
    lo = np.array([[at(l)[k][r] for r, l in enumerate(l0)] for k in range(2)])
    hi = np.array([[at(min(l + 1, 6))[k][r] for r, l in enumerate(l0)] for k in range(2)])
    mean, sq = lo + f * (hi - lo)
    t = (rx.depth.numpy() - view.near) / (view.far - view.near)
    var = np.maximum(sq - mean ** 2, spec.params.min_variance)
    want = np.where(t <= mean, 1.0, var / (var + (t - mean) ** 2))
    assert np.mean(np.abs(got - want) < 1e-3) > 0.995
    from dsm import prefilter
    flat = dataclasses.replace(rx, camera=None)
    plain_spec = dataclasses.replace(spec, mipmaps=False)
    plain = pl.moment_map(plain_spec, pl.build_map(sd.scene, view), "float32")
    np.testing.assert_array_equal(prefilter.visibility(spec, flat, mm).numpy(),
                                  prefilter.visibility(plain_spec, flat, plain).numpy())


@pytest.mark.parametrize("value", ["yes", 1, []])
def test_mipmaps_takes_booleans_only(value):
    from dsm.config import read as config
    with pytest.raises(config.ConfigError) as e:
        config.parse(base_config(map={"kind": ["vsm"], "mipmaps": value}), "<test>")
    assert e.value.key == "map.mipmaps"


def test_the_box_blur_is_the_clamped_window_mean_tap_by_tap_to_the_bit():
    """The separable box blur against its definition written out here: per axis, each texel's
    window of W texels (clamped at the face's edge) summed from 0 in window order, then / W; 30
    decades of values and signed zeros, as the exponential moments hold them."""
    from dsm.prefilter import base
    rng = np.random.default_rng(3)
    faces, R, W = 2, 9, 5
    x = np.exp(rng.normal(0, 20, faces * R * R))
    x[::5] = -x[::5]
    x[::7] = -0.0
    h = W // 2
    img = x.reshape(faces, R, R).copy()
    for axis in (1, 2):
        out = np.empty_like(img)
        for f in range(faces):
            for i in range(R):
                for j in range(R):
                    acc = 0
                    for k in range(-h, h + 1):
                        ii, jj = (min(max(i + k, 0), R - 1), j) if axis == 1 else (i, min(max(j + k, 0), R - 1))
                        acc = acc + img[f, ii, jj]
                    out[f, i, j] = acc / W
        img = out
    assert base.box_blur(x, W, faces, R).tobytes() == img.reshape(-1).tobytes()
