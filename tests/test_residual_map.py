"""The residual bias map's exact per-block fit against a brute-force scan (numpy float64), its
block keys against hand-made texel indices, and leave-one-camera-out choosing no residual
where nothing generalizes."""
import numpy as np
import pytest

from dsm.tune import residual_map as rm


def _brute(m, v, unit, keys, lam):
    """Per block the least errors over a fine scan of residuals (plus the flips' neighbourhoods)."""
    out = {}
    for k in np.unique(keys):
        s = keys == k
        f = -m[s] / unit[s]
        cands = np.concatenate([[f.min() - 1.0, 0.0], f - 1e-9, f + 1e-9, [f.max() + 1.0]])
        errs = [((m[s] + r * unit[s] < 0) & v[s]).sum() + lam * ((m[s] + r * unit[s] >= 0) & ~v[s]).sum() for r in cands]
        out[int(k)] = (min(errs), ((m[s] < 0) & v[s]).sum() + lam * ((m[s] >= 0) & ~v[s]).sum())
    return out


@pytest.mark.parametrize("lam", [1.0, 3.0])
def test_per_block_fit_is_the_exact_optimum(lam):
    rng = np.random.default_rng(5)
    n = 400
    keys = rng.integers(0, 30, n).astype(np.int64)
    m = rng.normal(0, 1, n)
    v = rng.random(n) < 0.5 + 0.3 * np.tanh(m)          # mostly lit where the margin is positive
    unit = rng.uniform(0.5, 2.0, n)
    fit = rm.fit_blocks(m, v, unit, keys, lam, margin=0.01)
    ref = _brute(m, v, unit, keys, lam)
    assert list(fit["keys"]) == sorted(ref)
    for k, e0, best, rho in zip(fit["keys"], fit["e0"], fit["best"], fit["rho"]):
        s = keys == k
        got = ((m[s] + rho * unit[s] < 0) & v[s]).sum() + lam * ((m[s] + rho * unit[s] >= 0) & ~v[s]).sum()
        assert (best, e0) == pytest.approx(ref[int(k)]) and got == pytest.approx(best), int(k)


def test_residual_nearest_zero_and_min_gain():
    """One block: two truly shadowed receivers lit at residual 0 (margins 0.5 and 0.8 texel), one
    truly lit at margin 3: any residual in (-3, -0.8] fixes both; the nearest 0 with a 0.1
    margin is -0.9; a min_gain of 3 keeps 0."""
    m, v, unit = np.array([0.5, 0.8, 3.0]), np.array([False, False, True]), np.ones(3)
    fit = rm.fit_blocks(m, v, unit, np.zeros(3, np.int64), 1.0, margin=0.1)
    assert fit["e0"][0] == 2 and fit["best"][0] == 0 and fit["rho"][0] == pytest.approx(-0.9)
    assert rm.residuals(fit, 2)[0] == pytest.approx(-0.9) and rm.residuals(fit, 3)[0] == 0.0


def test_block_keys_and_neighbours():
    R = 8
    # texels (i, j) = (3, 2) and (5, 2) on face 0, (3, 2) on face 1, of group 0; block 2
    tex = np.array([2 * R + 3, 2 * R + 5, R * R + 2 * R + 3])
    k = rm.block_keys(tex, np.zeros(3), np.full(3, R), 2)
    assert k[0] != k[1] and k[0] != k[2]
    # the block one to the right of (3, 2)'s block (1, 1) is (5, 2)'s block (2, 1)
    assert rm.block_keys(tex[:1], [0], [R], 2, di=1)[0] == k[1]


def test_validation_keeps_no_residual_when_nothing_generalizes():
    """Two cameras whose errors fall in different texels: a residual fitted on one only adds
    errors on the other, so leave-one-camera-out chooses none."""
    R = 16
    tex = np.arange(40)
    rx = {"m": np.full(80, 0.5), "v_star": np.ones(80, bool), "unit": np.ones(80),
          "texel": np.concatenate([tex, tex]), "group": np.zeros(80, np.int64), "resolution": np.full(80, R)}
    rx["v_star"][[3, 7]] = False                # camera a: texels 3 and 7 truly shadowed there
    rx["v_star"][[40 + 20, 40 + 30]] = False    # camera b: texels 20 and 30
    cam = np.array(["a"] * 40 + ["b"] * 40)
    ch = rm.choose(rx, cam, [1, 2], [0, 1], [1, 2], 1.0, 0.1)
    assert ch["chosen"] is None and ch["none"] == 4
    assert all(s["errors"] >= 4 for s in ch["scores"])


def test_validation_chooses_a_residual_where_errors_repeat_across_cameras():
    """Both cameras see texels 3 and 7 truly shadowed at margin 0.5 texel (lit there at residual
    0): a residual fitted on either camera fixes the other's, so a candidate is chosen, and it
    removes every error."""
    R = 16
    tex = np.arange(40)
    rx = {"m": np.full(80, 0.5), "v_star": np.ones(80, bool), "unit": np.ones(80),
          "texel": np.concatenate([tex, tex]), "group": np.zeros(80, np.int64), "resolution": np.full(80, R)}
    rx["v_star"][[3, 7, 43, 47]] = False
    cam = np.array(["a"] * 40 + ["b"] * 40)
    ch = rm.choose(rx, cam, [1], [0], [1, 2], 1.0, 0.1)
    # fitted on one camera a texel gains 1 error: min_gain 2 moves nothing there
    assert ch["none"] == 4 and ch["chosen"] == (1, 0, 1)
    assert {(s["min_gain"], s["errors"]) for s in ch["scores"]} == {(1, 0.0), (2, 4.0)}
    fit = rm.smoothed_fit(rx, 1, 0, 1.0, 0.1)
    m, hit = rm.apply(fit, 1, rx, 1)
    assert hit.all() and rm.errors(m, rx["v_star"], 1.0) == 0
    assert np.allclose(m[[3, 7]], -0.1)                         # residual -0.6: 0.1 texel inside


def test_tune_residual_map_reports_the_split_against_its_base():
    """dsm tune with fit = "residual": the map's held-out counts, where no residual was chosen,
    are the best global scheme's exact counts (the kit's lookup, recomputed here); the split's
    receivers add up to the held-out ones; no map beats the per-texel oracle of its receivers."""
    from dsm.tune import tuner as tu
    cams = [{"position": [3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
            {"position": [-4.0, -4.0, 5.0], "target": [0.0, 0.0, 0.0]},
            {"position": [-4.0, 3.0, 5.0], "target": [0.0, 0.0, 0.0], "role": "heldout"}]
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane_box"}],
           "map": {"resolution": 32}, "scheme": [{"name": "constant", "bias": "1 texel"}],
           "tune": {"steps": 8, "camera": cams, "bias_map": {"fit": "residual", "block": [2, 1], "radius": [0, 1],
                                                             "min_gain": [1, 2]}}}
    res = tu.tune(cfg)
    bm, best = res.bias_map, res.schemes[0]
    assert bm["fit"] == "residual" and len(bm["validation"]["scores"]) == 2 * 2 * 2
    sp = bm["heldout_split"]
    assert sp["covered"]["n_receivers"] + sp["uncovered"]["n_receivers"] == res.n_heldout
    for part in sp.values():
        if part["n_receivers"]:
            assert part["map"] >= part["per_texel_oracle"] - 1e-12
    if not bm["chosen"]:
        assert bm["heldout"]["objective"] == pytest.approx(best["heldout"]["objective"])
        assert (bm["heldout"]["n_acne"], bm["heldout"]["n_peterpan"]) == \
            (best["heldout"]["n_acne"], best["heldout"]["n_peterpan"])
    else:
        assert bm["blocks_moved"] > 0


@pytest.mark.parametrize("lam,margin", [(1.0, 0.02), (2.5, 0.5), (0.3, 0.0)])
def test_one_block_fit_is_fit_blocks_with_one_key(lam, margin):
    """fit_one_block (the edge map's threshold) gives fit_blocks' best and residual bit for bit, on ties,
    signed zeros, infinities and NaN margins alike."""
    rng = np.random.default_rng(11)
    for trial in range(300):
        n = int(rng.integers(1, 120))
        m = np.round(rng.normal(size=n), 1)                     # ties on purpose
        m[rng.random(n) < 0.1] = -0.0
        if trial % 3 == 1:
            m[rng.random(n) < 0.1] = np.nan
        if trial % 5 == 2:
            m[rng.random(n) < 0.1] = np.inf * rng.choice([-1.0, 1.0])
        v, unit = rng.random(n) < rng.random(), rng.uniform(0.5, 2.0, n)
        with np.errstate(invalid="ignore"):
            ref = rm.fit_blocks(m, v, unit, np.zeros(n, np.int64), lam, margin)
            best, rho = rm.fit_one_block(m, v, unit, lam, margin)
        assert np.array_equal([best, rho], [ref["best"][0], ref["rho"][0]], equal_nan=True), trial
        assert np.signbit(rho) == np.signbit(ref["rho"][0]), trial
