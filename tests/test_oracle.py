"""The oracles (dsm.truth.oracle): the best any bias can do, held to the kit's own sweeps and to
geometry derived here, independently of truth/oracle.py."""
import csv
import math
import numpy as np

import pytest

from conftest import base_config

LIGHTS = [{"type": "directional", "direction": [-0.3, -0.2, -1.0]},
          {"type": "spot", "position": [-2.0, 1.5, 4.0], "target": [0.0, 0.0, 0.0], "cutoff": 45},
          {"type": "point", "position": [0.3, -0.2, 2.5]}]
WORLD = [0.0, 0.002, 0.01, 0.05, 0.2]
TEXEL = [0.25, 0.5, 1.0, 3.0]


def _key(r):
    return (r["scene"], r["light"], r["view"], r["resolution"], r["culling"], r["format"])


def _curves(res):
    return {_key(row): (cw, ck) for row, cw, ck in res.curves}


def objective(r, lam=1.0):
    return (r["n_acne"] + lam * r["n_peterpan"]) / r["n_receivers"]


# ---------------------------------------------------------------- pure functions

def smallest_lit_float32(lit) -> np.ndarray:
    """Per element, the smallest float32 ``b`` with ``lit(b)`` (a predicate on float32 arrays, false at
    -inf and true at +inf, monotone in b): a bisection over every float32 value in order, their bit
    patterns mapped to ordered integers (32 halvings instead of a walk of up to 2^21 steps)."""
    def value(k):
        bits = np.where(k >= 0, k, -k | 0x80000000).astype(np.uint32)
        return bits.view(np.float32)
    inf = int(np.array(np.inf, np.float32).view(np.int32))
    lo, hi = np.full(lit.n, -inf, np.int64), np.full(lit.n, inf, np.int64)
    while (hi - lo > 1).any():
        mid = (lo + hi) // 2
        on = lit(value(mid))
        hi, lo = np.where(on, mid, hi), np.where(on, lo, mid)
    return value(hi)


def test_thresholds_are_the_smallest_float32_bias_that_lights():
    """Against a search over every float32 value near d - z1: z1 + b rounds monotonically in b, so
    the smallest bias that lights is where an exhaustive bisection of the ordered float32 values ends."""
    from dsm.truth import oracle
    rng = np.random.default_rng(1)
    z1 = rng.uniform(0.1, 50.0, 400).astype(np.float32)
    d = (z1 + rng.normal(0, 1e-4, 400) * z1).astype(np.float32)
    d[:20] = z1[:20]
    tw = rng.uniform(1e-3, 0.1, 400).astype(np.float32)
    tau, kappa = oracle.thresholds(z1, d), oracle.texel_thresholds(z1, d, tw)
    walk = d != z1
    lit = lambda b: (z1[walk] + b) - d[walk] >= 0       # float32 arrays: float32 sums, as the map rounds
    lit.n = int(walk.sum())
    assert (smallest_lit_float32(lit) == tau[walk]).all()
    for i in range(400):
        lit1 = lambda b: np.float32(np.float32(z1[i] + np.float32(b)) - d[i]) >= 0
        if d[i] == z1[i]:            # b = 0 lights it; the walk below zero would cross the subnormals
            assert lit1(tau[i]) and not lit1(np.nextafter(tau[i], np.float32(-np.inf))) and tau[i] <= 0
        litk = lambda k: np.float32(np.float32(z1[i] + np.float32(np.float32(k) * tw[i])) - d[i]) >= 0
        assert litk(kappa[i]) and not litk(np.nextafter(kappa[i], np.float32(-np.inf)))


def test_thresholds_tried_at_a_guess_first_are_the_bisections():
    """The thresholds (tried first where the float32 comparison turns, then bisected where that misses) are,
    bit for bit, an exhaustive bisection over every float32: near and far receivers, d = z1, d one float32
    off z1, negative and zero depths (+0 where both are zero), depths from 1e-30 to 1e30, texels 1e-7 to 10."""
    from dsm.truth import oracle
    rng = np.random.default_rng(5)
    n = 6000
    z1 = (rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-30, 30, n)).astype(np.float32)
    d = (z1 * (1 + rng.normal(0, 1e-3, n) * 10.0 ** rng.uniform(-6, 0, n))).astype(np.float32)
    d[:300] = z1[:300]
    d[300:600] = np.nextafter(z1[300:600], np.float32(np.inf))
    d[600:900] = np.nextafter(z1[600:900], np.float32(-np.inf))
    z1[900:1000], d[1000:1100] = 0.0, 0.0
    d[1100:1400] = rng.uniform(-5, 5, 300).astype(np.float32)          # far from z1: a large bias
    tw = (10.0 ** rng.uniform(-7, 1, n)).astype(np.float32)
    z1[1400:1500], d[1400:1500] = 0.0, -0.0                             # both zero: the threshold is +0
    lit = lambda b: (z1 + b) - d >= 0                                   # float32, as the map rounds
    litk = lambda k: (z1 + k * tw) - d >= 0
    lit.n = litk.n = n
    with np.errstate(over="ignore", invalid="ignore"):
        tau, kappa = oracle.thresholds(z1, d), oracle.texel_thresholds(z1, d, tw)
        assert np.array_equal(tau.view(np.int32), smallest_lit_float32(lit).view(np.int32))
        assert np.array_equal(kappa.view(np.int32), smallest_lit_float32(litk).view(np.int32))


def test_per_texel_oracle_against_brute_force():
    """Per texel, every candidate bias tried (the texel's thresholds and one below them all)."""
    from dsm.truth import oracle
    rng = np.random.default_rng(2)
    n = 3000
    tau = rng.normal(0, 1, n).round(1).astype(np.float32)          # ties on purpose
    v_star = rng.random(n) < 0.6
    texel = rng.integers(0, 200, n)
    for lam in (0.5, 1.0, 3.0):
        pt = oracle.per_texel(tau, v_star, texel, lam)
        total, wrong = 0.0, np.zeros(n, bool)
        for t in np.unique(texel):
            m = texel == t
            cands = np.concatenate([[-np.inf], np.unique(tau[m])])
            objs = [((v_star[m] & (tau[m] > b)).sum() + lam * (~v_star[m] & (tau[m] <= b)).sum()) for b in cands]
            b = cands[int(np.argmin(objs))]
            total += min(objs)
            wrong[m] = (tau[m] <= b) != v_star[m]
        assert pt["objective"] == pytest.approx(total / n)
        assert np.array_equal(pt["wrong"], wrong)


# ---------------------------------------------------------------- against the kit's sweeps

@pytest.mark.slow
@pytest.mark.parametrize("scene", ["plane_box", "room", "l_shape"])
def test_curve_equals_the_constant_sweep_count_for_count(run_dict, scene):
    """Every constant case (world and texel values), on all five views and two stored formats:
    the oracle's exact curve evaluated at the swept value gives the case's n_acne and n_peterpan."""
    cfg = base_config(scene=[{"builtin": scene}], light=LIGHTS, camera={"resolution": [64, 64]},
                      map={"resolution": 96, "view": ["paraboloid", "dual_paraboloid", "cube"],
                           "format": ["float32", "unorm16"], "filter": ["nearest", "pcf_bilinear"]},
                      scheme=[{"name": "constant", "bias": WORLD + [f"{k} texel" for k in TEXEL]}])
    res = run_dict(cfg)
    curves = _curves(res)
    rows = res.where(filter="nearest").rows
    assert {r["view"] for r in rows} == {"orthographic", "perspective", "paraboloid", "dual_paraboloid", "cube"}
    assert len(res.oracle) == 5 * 2
    checked = 0
    for r in rows:
        if not r["n_receivers"]:
            continue
        cw, ck = curves[_key(r)]
        value, unit = float(r["sweep_value"]), r["sweep_key"]
        acne, pp = (ck if "texel" in unit else cw).at(value)
        assert (int(acne), int(pp)) == (r["n_acne"], r["n_peterpan"]), (r["view"], r["format"], r["params"])
        checked += 1
        # the split adds up and the oracle's row matches the map
        assert r["n_acne_resolution"] + r["n_acne_bias"] == r["n_acne"]
        assert r["n_peterpan_resolution"] + r["n_peterpan_bias"] == r["n_peterpan"]
    assert checked >= 80
    for r in res.where(filter="pcf_bilinear").rows:
        assert math.isnan(r["n_acne_resolution"])
    # no swept value beats the oracles
    orc = {_key(o): o for o in res.oracle}
    for r in rows:
        if r["n_receivers"]:
            assert orc[_key(r)]["world_objective"] <= objective(r) + 1e-12 or "texel" in r["sweep_key"]
            assert orc[_key(r)]["texel_objective"] <= objective(r) + 1e-12 or "texel" not in r["sweep_key"]
            assert orc[_key(r)]["per_texel_objective"] <= objective(r) + 1e-12


@pytest.mark.slow
@pytest.mark.parametrize("azimuth", [0.0, 30.0])
def test_tilted_plane_needs_the_largest_texel_threshold(run_dict, azimuth):
    """The 45-degree plane under a light straight down: the depth within a texel is the plane's,
    so the smallest k that removes all acne is max over receivers of slope * (offset of the
    receiver from its texel centre along the slope direction in the map) / texel, about
    0.5 (|cos phi| + |sin phi|) for the grid's rotation phi. Derived from the receivers' map
    positions and a least-squares fit of the plane's depth in the map."""
    import dsm.pipeline as pl
    res = run_dict(base_config(scene=[{"builtin": "plane", "tilt": 45.0, "azimuth": azimuth}],
                               camera={"resolution": [96, 96]}, map={"resolution": 128},
                               scheme=[{"name": "constant", "bias": "1 texel"}]))
    o = res.oracle[0]
    assert o["n_gt_shadowed"] == 0 and o["n_receivers"] > 3000
    assert o["texel_n_acne"] == 0 and o["texel_objective"] == 0.0
    # the receivers' map positions, from the pipeline's stages
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane", "tilt": 45.0, "azimuth": azimuth}), (96, 96))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, pl.LightSpec("directional", direction=(0.0, 0.0, -1.0)), "sun")
    view = pl.make_view(setup.light, 128, pl.points_np(setup.p), sd.bbox)
    rx = pl.receivers(view, setup, sd.diagonal)
    u, v = rx.u_map.numpy().astype(np.float64), rx.v_map.numpy().astype(np.float64)
    p = pl.points_np(setup.p)
    tw = float(np.median(rx.texel_world.numpy()))
    depth = -p[:, 2]                                     # straight down: depth = -z + const
    A = np.stack([u, v, np.ones_like(u)], 1)
    (gu, gv, _), *_ = np.linalg.lstsq(A, depth, rcond=None)
    slope = math.hypot(gu, gv) / tw
    assert slope == pytest.approx(1.0, rel=1e-3)           # tan 45
    du, dv = u - (np.floor(u) + 0.5), v - (np.floor(v) + 0.5)
    expected = float(((gu * du + gv * dv) / tw).max())
    phi = math.atan2(gv, gu)
    assert expected == pytest.approx(0.5 * (abs(math.cos(phi)) + abs(math.sin(phi))), rel=0.03)
    assert o["best_k"] == pytest.approx(expected, rel=2e-3, abs=2e-4)
    # and the kit's constant at that k has no acne, one float32 below it has
    below = float(np.nextafter(np.float32(o["best_k"]), np.float32(-1)))
    res2 = run_dict(base_config(scene=[{"builtin": "plane", "tilt": 45.0, "azimuth": azimuth}],
                                camera={"resolution": [96, 96]}, map={"resolution": 128},
                                scheme=[{"name": "constant", "bias": [f"{o['best_k']!r} texel", f"{below!r} texel"]}]),
                    "check")
    assert res2.rows[0]["n_acne"] == 0 and res2.rows[1]["n_acne"] >= 1


@pytest.mark.slow
def test_floating_plate_best_bias_lies_below_the_gap(run_dict):
    """Gap 0.2: the best single bias removes every acne a receiver gets from its own surface
    (the largest such threshold, from the pipeline's taps) and stays below the gap; no swept
    constant does better."""
    import dsm.pipeline as pl
    sweep = [0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.15, 0.19, 0.25, "0.5 texel", "1 texel", "2 texel", "4 texel"]
    res = run_dict(base_config(scene=[{"builtin": "floating_plate", "gap": 0.2}], camera={"resolution": [96, 96]},
                               map={"resolution": 128}, scheme=[{"name": "constant", "bias": sweep}]))
    o = res.oracle[0]
    assert o["n_gt_shadowed"] > 100
    sd = pl.load_scene(pl.scene_spec({"builtin": "floating_plate", "gap": 0.2}), (96, 96))
    gb = pl.gbuffer(sd)
    light = sd.lights_for((pl.LightSpec("scene", label="scene"),))[0]       # the plate's own light
    setup = pl.light_setup(sd, gb, light, "0:directional")
    view = pl.make_view(setup.light, 128, pl.points_np(setup.p), sd.bbox)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool))
    rx = pl.receivers(view, setup, sd.diagonal)
    smap = pl.store(pl.build_map(sd.scene, view), "float32")
    _, tap_shape = pl.visibility(pl.scheme_spec({"name": "none"}), rx, smap)
    th = pl.thresholds(rx, smap)
    own = setup.v_star & (tap_shape.numpy() == setup.shape)
    largest_self = float(th.tau[own].max())
    assert 0 < largest_self <= o["best_b"] < 0.2
    assert o["best_b"] == pl.oracles(th, setup.v_star)["row"]["best_b"]
    for r in res.rows:
        assert o["world_objective"] <= objective(r) + 1e-12, r["params"]


@pytest.mark.slow
def test_per_texel_oracle_bounds_every_texel_only_scheme(run_dict):
    """Constant and slope-scaled in world or range units, midpoint, dual (world z_offset): the
    per-texel oracle's objective is at most each case's, on every map of a small run."""
    schemes = [{"name": "constant", "bias": [0.0, 0.01, 0.05, "0.001 range"]},
               {"name": "slope_scaled"}, {"name": "slope_scaled", "bias": 0.005, "slope": 2.0, "clamp": 0.1},
               {"name": "midpoint", "culling": "none"}, {"name": "dual", "z_offset": 0.1, "culling": "none"},
               {"name": "dual", "z_offset": 0.1, "culling": "back_closed"}]
    res = run_dict(base_config(scene=[{"builtin": s} for s in ("plane_box", "l_shape", "floating_plate")],
                               light=LIGHTS[:1] + LIGHTS[2:], camera={"resolution": [64, 64]},
                               map={"resolution": 128, "view": "cube"}, scheme=schemes,
                               oracle={"lambda": [1.0, 4.0]}))
    assert {o["lambda"] for o in res.oracle} == {1.0, 4.0}
    checked = 0
    for o in res.oracle:
        lam = o["lambda"]
        for r in res.rows:
            if _key(r) == _key(o) and r["n_receivers"]:
                assert o["per_texel_objective"] <= objective(r, lam) + 1e-12, (r["scheme"], r["params"], lam)
                assert o["per_texel_objective"] <= o["world_objective"] <= objective(r, lam) + 1e-12 or \
                    r["scheme"] != "constant" or "range" in r["params"]
                checked += 1
    assert checked >= 50
    # the split: resolution-limited errors are at most the per-texel oracle's errors
    for r in res.rows:
        o = next(x for x in res.oracle if _key(x) == _key(r) and x["lambda"] == 1.0)
        assert r["n_acne_resolution"] <= o["per_texel_n_acne"]
        assert r["n_peterpan_resolution"] <= o["per_texel_n_peterpan"]


def test_oracle_outputs(run_dict):
    """oracle.csv (one row per map, format and lambda), table.md's section, the trade-off plot,
    the error image's resolution classes, and the config's checks."""
    from dsm.config import read as config
    from dsm.truth import metrics
    from dsm.report import io as report
    from dsm.core.types import ConfigError
    res = run_dict(base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [64, 64]},
                               map={"resolution": 64, "format": ["float32", "unorm16"]},
                               scheme=[{"name": "constant", "bias": [0.0, 0.02]}], oracle={"lambda": [0.5, 1.0]}), report=True)
    rows = report.read_csv(res.out / "oracle.csv")
    assert len(rows) == 4 and {r["format"] for r in rows} == {"float32", "unorm16"}
    assert float(rows[0]["world_objective"]) == pytest.approx(res.oracle[0]["world_objective"])
    text = (res.out / "table.md").read_text()
    assert "## How far from the best" in text and "acne (resolution)" in text
    assert list((res.out / "plots").glob("tradeoff_*.png"))
    r = res.rows[0]
    img = res.images[r["case"]]
    assert (img == metrics.ACNE_RESOLUTION).sum() == r["n_acne_resolution"]
    assert (img == metrics.ACNE).sum() == r["n_acne_bias"]
    assert len(metrics.CLASS_NAMES) == len(metrics.CLASS_COLORS) == 8
    for bad, msg in (({"lambda": -1.0}, ">= 0"), ({"lambda": "one"}, "number"), ({"lam": 1.0}, "unknown key"),
                     ({"lambda": []}, "empty")):
        with pytest.raises(ConfigError, match=msg):
            config.parse(base_config(oracle=bad), "<t>")
    assert config.parse(base_config(oracle={"lambda": [1, 2.5]}), "<t>").oracle.lambdas == (1.0, 2.5)
    assert config.parse(base_config(), "<t>").oracle.lambdas == (1.0,)


def test_plan_counts_the_oracles_sorts():
    from dsm.config import read as config
    from dsm.config import plan
    cfg = config.parse(base_config(camera={"resolution": [64, 32]}, map={"resolution": [64, 128],
                                   "format": ["float32", "unorm16"]}, oracle={"lambda": [1.0, 2.0]}), "<t>")
    p = plan.make(cfg)
    assert p.oracle_receivers == 2 * 2 * 64 * 32          # 2 maps x 2 formats x camera pixels
    line = next(x for x in p.text().splitlines() if "oracles" in x)
    assert f"{2 * 2 * 64 * 32:,}" in line and "2 lambda" in line


def test_an_oracle_bias_pasted_back_gives_the_oracles_counts(tmp_path):
    """oracle.csv's best world bias, read as text and pasted into a config as a constant bias,
    gives the world oracle's acne and peter-panning counts (6 digits gave one more acne receiver)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [96, 96]}, map={"resolution": 128},
                      scheme=[{"name": "none"}])
    first = dsm.run(raw, out=tmp_path / "a", report=False)
    rows = list(csv.DictReader(open(first.out / "oracle.csv")))
    # every best bias reads back to the oracle's own float (6 digits did not)
    assert [float(r["best_b"]) for r in rows] == [o["best_b"] for o in first.oracle]
    assert [float(r["best_k"]) for r in rows] == [o["best_k"] for o in first.oracle]
    row = rows[0]
    pasted = dsm.run({**raw, "scheme": [{"name": "constant", "bias": float(row["best_b"])}]}, out=tmp_path / "b", report=False)
    r = pasted.rows[0]
    assert (r["n_acne"], r["n_peterpan"]) == (int(row["world_n_acne"]), int(row["world_n_peterpan"]))
