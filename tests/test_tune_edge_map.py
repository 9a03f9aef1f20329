"""The edge bias map (dsm.tune.edge_map): its tent score against bilinear interpolation written out
in numpy float64, its exact threshold and candidate fit against brute-force scans, the 3 x 3 taps'
margins against the depth test recomputed from the map's z1, and the [tune.bias_map] keys it refuses."""
import numpy as np
import pytest

from dsm.tune import edge_map as em

CAMS = [{"position": [3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
        {"position": [-4.0, -3.0, 5.0], "target": [0.0, 0.0, 0.0], "role": "heldout"}]


def _random_rx(n, seed):
    rng = np.random.default_rng(seed)
    tw = rng.uniform(0.5, 2.0, n)
    m9 = rng.normal(0, 3, (n, 9)) * tw[:, None]
    fx, fy = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n)
    cos = rng.uniform(0, 1, n)
    v = rng.random(n) < 0.5 + 0.4 * np.tanh(m9[:, 4] / tw)
    return {"m9": m9, "fx": fx, "fy": fy, "unit": tw, "cos": cos, "v_star": v}


def test_tent_of_half_width_one_is_bilinear_on_the_votes():
    """Width 1: the 2 x 2 taps around the receiver, bilinear weights (written out per quadrant)."""
    rx = _random_rx(500, 1)
    clip = 1.5
    got = em.tent_score(rx["m9"], rx["fx"], rx["fy"], rx["unit"], 1.0, clip)
    votes = np.clip(rx["m9"] / (clip * rx["unit"][:, None]), -1, 1)
    for r in range(500):
        fx, fy = rx["fx"][r], rx["fy"][r]
        a, b = (1 if fx >= 0 else -1), (1 if fy >= 0 else -1)
        wx, wy = abs(fx), abs(fy)
        col = lambda i, j: votes[r, (j + 1) * 3 + (i + 1)]
        ref = ((1 - wx) * (1 - wy) * col(0, 0) + wx * (1 - wy) * col(a, 0) + (1 - wx) * wy * col(0, b)
               + wx * wy * col(a, b))
        assert got[r] == pytest.approx(ref, abs=1e-12)


def test_agreeing_taps_keep_the_base_answer():
    """Where every tap's margin has one sign beyond the clip, the score is +-1 whatever the width."""
    rx = _random_rx(200, 2)
    sign = np.where(rx["m9"][:, 4] >= 0, 1.0, -1.0)
    m9 = sign[:, None] * (5.0 + np.abs(rx["m9"])) * rx["unit"][:, None]
    for width in (0.75, 1.0, 1.5):
        s = em.tent_score(m9, rx["fx"], rx["fy"], rx["unit"], width, 4.0)
        assert np.array_equal(s, sign)


@pytest.mark.parametrize("lam", [1.0, 2.5])
def test_exact_threshold_is_the_brute_force_optimum(lam):
    rng = np.random.default_rng(3)
    x = np.round(rng.normal(0, 0.5, 300), 2)          # ties on purpose
    v = rng.random(300) < 0.5 + 0.4 * np.tanh(3 * x)
    t, e = em.exact_threshold(x, v, lam)
    cands = np.concatenate([np.unique(x) - 1e-9, np.unique(x) + 1e-9, [x.min() - 1, x.max() + 1]])
    errs = [((x < c) & v).sum() + lam * ((x >= c) & ~v).sum() for c in cands]
    assert e == pytest.approx(min(errs))
    assert ((x < t) & v).sum() + lam * ((x >= t) & ~v).sum() == pytest.approx(e)


def test_fit_picks_the_fewest_training_errors_of_the_grid():
    rx = _random_rx(400, 4)
    widths, clips, grazings = (1.0, 1.5), (0.5, 4.0), (0.0, 0.5)
    model = em.fit(rx, widths, clips, grazings, 1.0)
    assert len(model["scores"]) == 8
    brute = []
    for w in widths:
        for c in clips:
            for g in grazings:
                x = em.tent_score(rx["m9"], rx["fx"], rx["fy"], rx["unit"], w, c) - g * (1 - rx["cos"])
                thr = np.unique(x)
                brute.append(min(((x < t) & rx["v_star"]).sum() + ((x >= t) & ~rx["v_star"]).sum()
                                 for t in np.concatenate([thr, [thr.max() + 1]])))
    assert model["errors"] == min(brute)
    assert (em.lit(rx, model) != rx["v_star"]).sum() == model["errors"]


def test_neighbour_margins_are_the_depth_test_at_each_tap():
    """A constant world bias, no shift: the margin with tap (a, b) is z1 of texel (i + a, j + b) + bias
    - depth, recomputed from the map's z1 (float64) where the 3 x 3 lies inside the face."""
    import dsm.pipeline as pl
    from dsm.tune import tuner as tu, cases as tcase
    from dsm.tune.bias_map import margin_arrays, neighbour_margins
    from dsm.config.read import coerce
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "floating_plate"}],
           "map": {"resolution": 32}, "scheme": [{"name": "constant", "bias": 0.02}], "tune": {"camera": CAMS}}
    tc = tu.parse_tune(coerce(cfg))
    tc.config = pl.prepare(tc.config)
    groups, cases, _ = tcase.prepare_cases(tc)
    spec = tc.schemes[0]
    rx = neighbour_margins(spec, cases, groups)
    assert np.array_equal(rx["m9"][:, 4], margin_arrays(spec, cases, groups)["m"])
    R = groups[0].view.resolution
    z1 = np.asarray(groups[0].maps["none"].z1.numpy(), np.float64)
    u = np.concatenate([np.asarray(c.rx.u_map.numpy(), np.float64) for c in cases])
    v = np.concatenate([np.asarray(c.rx.v_map.numpy(), np.float64) for c in cases])
    d = np.concatenate([np.asarray(c.rx.depth.numpy(), np.float64) for c in cases])
    i, j = np.floor(u).astype(int), np.floor(v).astype(int)
    inside = (i >= 1) & (i <= R - 2) & (j >= 1) & (j <= R - 2)
    assert inside.sum() > 100
    assert np.allclose(rx["fx"], u - i - 0.5, atol=1e-6)
    for k, (a, b) in enumerate(em.OFFSETS):
        ref = z1[(j + b).clip(0, R - 1) * R + (i + a).clip(0, R - 1)] + 0.02 - d
        ok = inside & np.isfinite(ref)
        assert np.allclose(rx["m9"][ok, k], ref[ok], rtol=0, atol=1e-5), (a, b)


@pytest.mark.parametrize("bias_map,key", [
    ({"fit": "adam", "width": [1.0]}, "tune.bias_map.width"),           # edge keys only with fit = "edge"
    ({"fit": "residual", "grazing": [0.5]}, "tune.bias_map.grazing"),
    ({"fit": "edge", "width": [0.5]}, "tune.bias_map.width"),           # could miss every tap
    ({"fit": "edge", "width": [2.0]}, "tune.bias_map.width"),           # beyond the 3 x 3 taps
    ({"fit": "edge", "clip": []}, "tune.bias_map.clip"),
    ({"fit": "edge", "clip": [0]}, "tune.bias_map.clip"),
    ({"fit": "edge", "grazing": [-1]}, "tune.bias_map.grazing"),
    ({"fit": "edge", "block": [1, 2]}, "tune.bias_map.block"),          # one block: the held-out split's
    ({"fit": "edge", "steps": 5}, "tune.bias_map.steps"),               # fitted exactly: no Adam
])
def test_edge_keys_are_refused_before_work(bias_map, key):
    from dsm import ConfigError
    from dsm.config.read import coerce
    from dsm.tune import tuner as tu
    cfg = {"experiment": {"name": "t"}, "scene": [{"builtin": "plane"}], "scheme": [{"name": "constant"}],
           "tune": {"camera": CAMS, "bias_map": bias_map}}
    with pytest.raises(ConfigError) as e:
        tu.parse_tune(coerce(cfg))
    assert e.value.key == key


def test_edge_defaults():
    from dsm.config.read import coerce
    from dsm.tune import tuner as tu
    cfg = {"experiment": {"name": "t"}, "scene": [{"builtin": "plane"}], "scheme": [{"name": "constant"}],
           "tune": {"camera": CAMS, "bias_map": {"fit": "edge"}}}
    bm = tu.parse_tune(coerce(cfg)).spec.bias_map
    assert (bm.fit, bm.block, bm.widths[0], len(bm.clips), bm.grazings[0]) == ("edge", 2, 1.0, 5, 0.0)


@pytest.mark.slow
def test_edge_map_in_a_tune_run(tmp_path):
    """dsm tune with fit = "edge": the held-out split recounted from the fitted model on the 3 x 3
    margins of the best scheme, and the model written into table.md and tune.json."""
    import json
    from dsm.tune import tuner as tu
    from dsm.tune.bias_map import neighbour_margins
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "floating_plate"}],
           "map": {"resolution": 32}, "scheme": [{"name": "constant", "bias": 0.02}],
           "tune": {"steps": 8, "camera": CAMS, "bias_map": {"fit": "edge", "width": [1.0, 1.5], "clip": [1.0],
                                                              "grazing": [0.0, 0.5]}}}
    res = tu.tune(cfg, out=tmp_path)
    bm = res.bias_map
    assert bm["fit"] == "edge" and len(bm["candidates"]) == 4
    import dsm.pipeline as pl
    from dsm.config.read import coerce
    from dsm.tune import cases as tcase
    tc = tu.parse_tune(coerce(cfg))
    tc.config = pl.prepare(tc.config)
    groups, cases, _ = tcase.prepare_cases(tc)
    held = [c for c in cases if c.role == "heldout"]
    rx = neighbour_margins(res.schemes[0]["spec"], held, groups)
    from dsm.tune.residual_map import block_keys
    shared = em.lit(rx, bm["model"])
    assert bm["heldout_shared"]["n_acne"] == int((~shared & rx["v_star"]).sum())
    assert bm["heldout_shared"]["n_peterpan"] == int((shared & ~rx["v_star"]).sum())
    # the per-texel offsets as texel_offsets.npy holds them (texel key, offset), each receiver's read by its texel
    keys_fit, offsets = np.load(tmp_path / "texel_offsets.npy")
    assert bm["offsets"]["n_samples"] > 0 and bm["offsets"]["texels"] == keys_fit.size
    table = dict(zip(keys_fit.astype(np.int64).tolist(), offsets.tolist()))
    mine = np.array([table.get(int(k), 0.0) for k in block_keys(rx["texel"], rx["group"], rx["resolution"], 1)])
    on = em.over_threshold(rx, bm["model"]) + mine >= 0
    assert bm["heldout"]["n_acne"] == int((~on & rx["v_star"]).sum())
    assert bm["heldout"]["n_peterpan"] == int((on & ~rx["v_star"]).sum())
    split = bm["heldout_split"]
    assert split["covered"]["n_receivers"] + split["uncovered"]["n_receivers"] == rx["v_star"].size
    # receivers per texel recounted from (map, texel) pairs, the oracle's strength beside the gap closed
    from dsm.tune.residual_map import block_keys
    rx_tr = neighbour_margins(res.schemes[0]["spec"], [c for c in cases if c.role == "train"], groups)
    keys = lambda r: block_keys(r["texel"], r["group"], r["resolution"], bm["block"])
    cov = np.isin(keys(rx), keys(rx_tr))
    assert cov.sum() == split["covered"]["n_receivers"]
    pairs = {(int(g), int(t)) for g, t in zip(rx["group"][cov], rx["texel"][cov])}
    assert split["covered"]["receivers_per_texel"] == pytest.approx(cov.sum() / len(pairs))
    for name, sel in (("covered", cov), ("uncovered", ~cov)):      # the in-sample refit: never above the map
        assert split[name]["refit"] <= split[name]["map"]
    assert "an edge map over constant" in (tmp_path / "table.md").read_text()
    assert "per-texel offset fitted exactly to" in (tmp_path / "table.md").read_text()
    assert "(in-sample)" in (tmp_path / "table.md").read_text()
    assert json.loads((tmp_path / "tune.json").read_text())["bias_map"]["model"] == pytest.approx(bm["model"])


def test_edge_refit_is_the_family_minimum_on_each_held_out_subset():
    """The in-sample refit fits the edge map to held-out receivers: on each subset its objective is
    the fewest errors over every candidate and every threshold, found here by a brute-force scan of
    all thresholds in float64, and never above a model fitted elsewhere (the trained map)."""
    from types import SimpleNamespace
    from dsm.tune.bias_map import edge_refits
    rx = _random_rx(400, 5)
    rx.update(texel=np.arange(400) // 2, group=np.zeros(400, np.int64))
    covered = np.random.default_rng(6).random(400) < 0.6
    bm = SimpleNamespace(widths=[1.0, 1.5], clips=[0.5, 2.0], grazings=[0.0, 0.5])
    lam = 2.0
    got = edge_refits(rx, covered, bm, lam)
    trained = em.fit(_random_rx(400, 7), bm.widths, bm.clips, bm.grazings, lam)
    for name, sel in (("covered", covered), ("uncovered", ~covered)):
        v = rx["v_star"][sel]
        best = np.inf
        for w in bm.widths:
            for c in bm.clips:
                s = em.tent_score(rx["m9"][sel], rx["fx"][sel], rx["fy"][sel], rx["unit"][sel], w, c)
                for g in bm.grazings:
                    x = em.needed(s, rx["cos"][sel], g)
                    for t in np.append(np.unique(x), np.inf):
                        lit = x >= t
                        best = min(best, (v & ~lit).sum() + lam * (~v & lit).sum())
        assert got[name]["refit"] == pytest.approx(best / sel.sum(), abs=1e-12)
        on = em.lit({k: np.asarray(a)[sel] for k, a in rx.items()}, trained)
        assert got[name]["refit"] <= ((v & ~on).sum() + lam * (~v & on).sum()) / sel.sum()


def test_edge_crossfit_counts_each_half_with_the_other_halfs_fit():
    """Cross-fitted by halves: each halving of the texels recomputed here in Python's integers (a
    splitmix-style hash of texel, group and the halving's number, its top bit), the receivers of one
    texel always in one half, each half counted under the model fitted on the other, the count
    averaged over the halvings."""
    from types import SimpleNamespace
    from dsm.tune.bias_map import CROSSFIT_SPLITS, edge_refits, texel_fold
    M = 2 ** 64
    rx = _random_rx(600, 9)
    rng = np.random.default_rng(10)
    rx.update(texel=rng.integers(0, 200, 600), group=rng.integers(0, 2, 600))
    bm = SimpleNamespace(widths=[1.0, 1.25], clips=[1.0, 4.0], grazings=[0.0, 0.25])
    lam = 1.5
    want = []
    for split in range(CROSSFIT_SPLITS):
        fold = []
        for t, g in zip(rx["texel"], rx["group"]):
            k = (int(t) * 0x9E3779B97F4A7C15 + int(g) * 0xBF58476D1CE4E5B9 + split * 0x94D049BB133111EB) % M
            k = ((k ^ (k >> 31)) * 0xD6E8FEB86659FD93) % M
            fold.append(k >> 63)
        fold = np.array(fold)
        assert np.array_equal(texel_fold(rx["texel"], rx["group"], split), fold)
        assert 0.3 < fold.mean() < 0.7
        total = 0.0
        for f in (0, 1):
            a = {k: np.asarray(x)[fold == f] for k, x in rx.items()}
            b = {k: np.asarray(x)[fold != f] for k, x in rx.items()}
            on = em.lit(b, em.fit(a, bm.widths, bm.clips, bm.grazings, lam))
            total += (b["v_star"] & ~on).sum() + lam * (~b["v_star"] & on).sum()
        want.append(total)
    got = edge_refits(rx, np.ones(600, bool), bm, lam)["covered"]
    assert got["crossfit"] == pytest.approx(np.mean(want) / 600, abs=1e-12)


def test_edge_refit_of_an_empty_subset_is_undefined():
    """Every held-out receiver in trained blocks: the rest has no refit (NaN, no model), not 0; one
    texel alone leaves a fold empty, so its cross-fit is undefined too."""
    from types import SimpleNamespace
    from dsm.tune.bias_map import edge_refits
    rx = _random_rx(50, 8)
    rx.update(texel=np.zeros(50, np.int64), group=np.zeros(50, np.int64))
    got = edge_refits(rx, np.ones(50, bool), SimpleNamespace(widths=[1.0], clips=[1.0], grazings=[0.0]), 1.0)
    assert np.isnan(got["uncovered"]["refit"]) and got["uncovered"]["refit_model"] is None
    assert np.isnan(got["uncovered"]["crossfit"]) and np.isnan(got["covered"]["crossfit"])
    assert got["covered"]["refit"] >= 0.0 and got["covered"]["refit_model"]["width"] == 1.0


def test_edge_samples_keys():
    """samples and layers: integers in range, samples 0 turning the offsets off; refused with another fit."""
    from dsm import ConfigError
    from dsm.config.read import coerce
    from dsm.tune import tuner as tu
    base = {"experiment": {"name": "t"}, "scene": [{"builtin": "plane"}], "scheme": [{"name": "constant"}]}
    parse = lambda bmap: tu.parse_tune(coerce({**base, "tune": {"camera": CAMS, "bias_map": bmap}})).spec.bias_map
    assert (parse({"fit": "edge", "samples": 0}).samples, parse({"fit": "edge", "layers": 3}).layers) == (0, 3)
    for bmap, key in (({"fit": "edge", "samples": -1}, "tune.bias_map.samples"),
                      ({"fit": "edge", "samples": 17}, "tune.bias_map.samples"),
                      ({"fit": "edge", "samples": 2.5}, "tune.bias_map.samples"),
                      ({"fit": "edge", "layers": 0}, "tune.bias_map.layers"),
                      ({"fit": "residual", "samples": 2}, "tune.bias_map.samples"),
                      ({"fit": "adam", "samples": 2}, "tune.bias_map.samples")):
        with pytest.raises(ConfigError) as e:
            parse(bmap)
        assert e.value.key == key


def test_texel_offsets_are_each_texels_exact_optimum():
    """fit_offsets against a brute-force scan per texel in float64: every offset reaches the fewest
    errors of "lit iff x + r >= 0" over all r, and lies within THRESHOLD_MARGIN of 0 wherever 0 already
    reaches them (kept that far inside its interval); a texel without samples reads 0."""
    rng = np.random.default_rng(3)
    n = 3000
    keys = rng.integers(0, 60, n) * 7 + 5
    x = rng.normal(0, 0.6, n)
    v = rng.random(n) < 1 / (1 + np.exp(-4 * (x + rng.normal(0, 0.3, 60)[keys // 7])))
    # two texels every sample of which is in shadow, below the threshold: 0 is optimal, and below every cut
    x = np.r_[x, -0.5, -0.3, -0.01]
    v = np.r_[v, False, False, False]
    keys = np.r_[keys, 1000, 1000, 1001]
    n = x.size
    lam = 1.5
    keys_fit, off = em.fit_offsets(x, v, keys, lam)
    assert np.array_equal(keys_fit, np.unique(keys))
    for k, r in zip(keys_fit, off):
        sel = keys == k
        err = lambda rr: (v[sel] & (x[sel] + rr < 0)).sum() + lam * (~v[sel] & (x[sel] + rr >= 0)).sum()
        cuts = np.unique(-x[sel])
        best = min(err(c) for c in np.r_[cuts - 1.0, cuts, cuts + 1e-9])
        assert err(r) == best
        if err(0.0) == best:
            assert abs(r) <= em.THRESHOLD_MARGIN
    assert (off != 0).any()
    # every sample shadowed: 0 where it lies THRESHOLD_MARGIN inside the interval below the first cut,
    # else the margin's edge (1001's cut is 0.01 above 0: -0.01)
    assert off[keys_fit == 1000][0] == 0.0
    assert off[keys_fit == 1001][0] == pytest.approx(0.01 - em.THRESHOLD_MARGIN, abs=1e-12)
    got = em.offset_at(keys_fit, off, np.array([keys_fit[3], 4, keys_fit[-1] + 1]))
    assert list(got) == [off[3], 0.0, 0.0]


def test_light_samples_of_the_floating_plate_match_its_shadow():
    """The floating plate's light samples (2 x 2 rays a texel): on the ground a sample is in shadow
    exactly where its ray to the light crosses the 1.5 x 1.5 plate at z = 0.2 (projected in float64
    here, samples within 1e-4 of the shadow's edge skipped), and the plate's samples are lit."""
    import dsm.pipeline as pl
    from dsm.config.read import coerce
    from dsm.tune import cases as tcase, light_samples
    from dsm.tune import tuner as tu
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "floating_plate"}],
           "map": {"resolution": 32}, "scheme": [{"name": "constant", "bias": 0.02}],
           "tune": {"steps": 8, "camera": CAMS, "bias_map": {"fit": "edge"}}}
    tc = tu.parse_tune(coerce(cfg))
    tc.config = pl.prepare(tc.config)
    groups, _, _ = tcase.prepare_cases(tc)
    cases = list(light_samples.sample_cases(groups[0], 0, 2, 4))
    p = np.concatenate([pl.points_np(c.setup.p) for c in cases])
    v = np.concatenate([c.v_star for c in cases])
    assert p.shape[0] == v.size > 1000 and all(c.role == "light" for c in cases)
    d = np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])
    ground, plate = np.abs(p[:, 2]) < 1e-4, np.abs(p[:, 2] - 0.2) < 1e-4
    assert (ground | plate).all()
    q = p[ground, :2] - (0.2 / -d[2]) * d[:2]           # along -d up to the plate's height
    inside = (np.abs(q) < 0.75).all(1)
    clear = np.min(np.abs(np.abs(q) - 0.75), axis=1) > 1e-4
    assert np.array_equal(v[ground][clear], ~inside[clear])
    assert v[plate].all()
    assert (~v[ground][clear]).sum() >= 50           # the comparison above is not vacuous: the shadow is sampled
    # traced in other chunks (997 rays, splitting texels and layers), the same samples with the same labels
    import dsm.tune.light_samples as ls
    small = pytest.MonkeyPatch()
    small.setattr(ls, "CHUNK_RAYS", 997)
    try:
        again = list(ls.sample_cases(groups[0], 0, 2, 4))
    finally:
        small.undo()
    rows = lambda cs: np.unique(np.c_[np.concatenate([pl.points_np(c.setup.p) for c in cs]),
                                     np.concatenate([c.v_star for c in cs])], axis=0)
    assert len(again) > len(cases) and np.array_equal(rows(again), rows(cases))


@pytest.mark.slow
def test_a_base_scheme_that_reads_the_camera_gets_no_offsets(tmp_path):
    """distance_normal scales its offset by the distance to the camera that sees each receiver; light
    samples have no camera, so the edge map over it keeps its shared threshold: its verdicts with and
    without offsets are the same, and table.md says why."""
    from dsm.tune import tuner as tu
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "floating_plate"}],
           "map": {"resolution": 32}, "scheme": [{"name": "distance_normal"}],
           "tune": {"steps": 8, "camera": CAMS, "bias_map": {"fit": "edge", "width": [1.0], "clip": [1.0],
                                                              "grazing": [0.0]}}}
    bm = tu.tune(cfg, out=tmp_path).bias_map
    assert bm["offsets"]["n_samples"] == 0 and bm["offsets"]["texels"] == 0
    assert bm["heldout"] == bm["heldout_shared"] and bm["train"] == bm["train_shared"]
    assert "which light samples lack" in (tmp_path / "table.md").read_text()
    assert "shared threshold (no offsets)" not in (tmp_path / "table.md").read_text()
    assert not (tmp_path / "texel_offsets.npy").exists()


@pytest.mark.slow
def test_force_without_offsets_leaves_no_stale_offsets_file(tmp_path):
    """A tune with offsets, then one without into the same folder with force: texel_offsets.npy goes
    with the rest of the previous tune's files (tune.json says no offsets; the file must not say otherwise)."""
    import json
    from dsm.tune import tuner as tu
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "floating_plate"}],
           "map": {"resolution": 32}, "scheme": [{"name": "constant", "bias": 0.02}],
           "tune": {"steps": 8, "camera": CAMS, "bias_map": {"fit": "edge", "width": [1.0], "clip": [1.0],
                                                              "grazing": [0.0], "samples": 2}}}
    tu.tune(cfg, out=tmp_path)
    assert (tmp_path / "texel_offsets.npy").exists()
    cfg["tune"]["bias_map"]["samples"] = 0
    tu.tune(cfg, out=tmp_path, force=True)
    assert json.loads((tmp_path / "tune.json").read_text())["bias_map"]["offsets"] is None
    assert not (tmp_path / "texel_offsets.npy").exists()


def test_samples_beyond_the_ray_budget_are_refused_before_tuning(tmp_path):
    """samples = 16 on the room's 256^2 cube map: 6 x 256^2 x 16^2 = 100,663,296 light rays, above
    MAX_RAYS (2^26): refused naming tune.bias_map.samples and the most that fits, floor(sqrt(2^26 /
    393,216)) = 13, and nothing written."""
    from dsm import ConfigError
    from dsm.tune import light_samples
    from dsm.tune import tuner as tu
    assert light_samples.MAX_RAYS == 2 ** 26
    inside = [{"position": [2.8, -2.8, 2.7], "target": [-0.6, 0.6, 0.4], "fov": 75.0},
              {"position": [-2.8, 2.8, 2.7], "target": [0.6, -0.6, 0.4], "fov": 75.0, "role": "heldout"}]
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "room"}],
           "map": {"resolution": 256, "view": "cube"}, "scheme": [{"name": "constant", "bias": 0.02}],
           "tune": {"steps": 8, "camera": inside, "bias_map": {"fit": "edge", "samples": 16}}}
    with pytest.raises(ConfigError) as e:
        tu.tune(cfg, out=tmp_path / "out")
    assert e.value.key == "tune.bias_map.samples" and "samples = 13 or fewer" in str(e.value)
    assert not (tmp_path / "out" / "tune.json").exists()
