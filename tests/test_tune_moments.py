"""dsm tune of pre-filtered maps (dsm.tune.moments): an unfiltered VSM tuned to the depth map's
exact world oracle (on one map it is a depth test with one bias), the forward-mode gradient
against central differences of a numpy float64 loss, never worse than its start nor than a grid of
as many evaluations, the written values reproducing their objective, kinds without a lookup-time
parameter noted."""
import math
import tomllib

import pytest

CAM = [{"position": [3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]}]


def _cfg(kinds, blur, steps=40, scene=None, **kind_tables):
    return {"experiment": {"name": "tm"}, "camera": {"resolution": [64, 64]},
            "scene": [scene or {"builtin": "l_shape"}], "light": [{"type": "scene"}],
            "map": {"resolution": 96, "kind": kinds, "blur": blur, **kind_tables},
            "tune": {"steps": steps, "camera": CAM}}


@pytest.fixture(scope="module")
def vsm_run(tmp_path_factory):
    from dsm.tune.tuner import tune
    out = tmp_path_factory.mktemp("tm")
    return tune(_cfg(["vsm"], [1, 5]), out=out), out


@pytest.mark.slow
def test_unfiltered_vsm_tuned_reaches_the_world_oracle_of_its_one_map(vsm_run):
    """At W = 1 VSM lights a receiver iff (t - t1)^2 <= min_variance (1 - q) / q (q from the bleed):
    one bias in normalized depth, on one map one world bias, so its best is the depth map's world
    oracle (a sorted sweep over the receivers' thresholds, dsm.truth.oracle). Rounding of t in
    float32 may move a receiver or two either way."""
    res, _ = vsm_run
    e = next(e for e in res.moments if e["filter"] == "box:1")
    oracle = e["depth_oracle_train"]["world"]
    two = 2.0 / res.n_train
    assert oracle - two <= e["train"] <= oracle * 1.05 + two, (e["train"], oracle)
    assert e["start_train"] > 2 * oracle              # the default (1e-4) is far from it: the tune moved


def test_tuned_never_worse_than_its_start_nor_the_grid(vsm_run):
    res, _ = vsm_run
    for e in res.moments:
        assert e["train"] <= e["start_train"] and e["train"] <= e["grid"]["train"], e["label"]
        assert e["grid"]["evaluations"] <= res.spec.steps


def test_forward_mode_gradient_matches_central_differences(vsm_run):
    """The derivative the optimizer steps on against a central difference of the same relaxed loss
    computed from the kit's forward V in numpy float64 (dsm.tune.moments.relaxed_loss_np)."""
    res, _ = vsm_run
    for e in res.moments:
        for name, g in e["gradcheck"].items():
            assert g["fd"] != 0 and g["rel_error"] < 0.05, (e["label"], name, g)


def test_the_written_values_reproduce_their_objective(vsm_run):
    """tuned.toml's values, pasted back, give the reported training objective exactly."""
    import dsm.pipeline as pl
    from dsm.config.read import coerce
    from dsm.report.tables import objective
    from dsm.tune import cases as tcase, moments, tuner
    res, out = vsm_run
    text = (out / "tuned.toml").read_text()
    blocks = text.split("# [map.vsm]\n")[1:]
    assert len(blocks) == len(res.moments) == 2
    for block, e in zip(blocks, res.moments):
        lines = [l[2:] for l in block.splitlines() if l.startswith("# ") and " = " in l and "objective" not in l]
        values = tomllib.loads("\n".join(lines))
        assert set(values) == {"min_variance", "bleed", "bleed_high"}       # every parameter, pasted whole
        assert {k: values[k] for k in e["values"]} == e["values"]
        tc = tuner.parse_tune(coerce(_cfg(["vsm"], [int(e["filter"].split(":")[1])], vsm=values)))
        tc.config = pl.prepare(tc.config)
        groups, cases, _ = tcase.prepare_cases(tc)
        spec = tc.config.map.moments[0]
        mm = moments.moment_maps(spec, cases, groups, "float32")
        assert objective(moments.hard_counts(spec, cases, mm), 1.0) == e["train"]


def test_esm_exponent_tuned_exactly_to_the_world_oracle_of_its_one_map():
    """ESM's c shapes the stored moment (a build per value): searched exactly, no gradient. At W = 1
    V = exp(-c (t - t1)) >= 1/2 iff t - t1 <= ln 2 / c: one bias in normalized depth, so on one map
    its best is the world oracle where that bias is within the box's reach (ln 2 / 88 to ln 2)."""
    from dsm.tune.tuner import tune
    res = tune(_cfg(["esm"], [1], steps=30))
    (e,) = res.moments
    assert e["rebuilt"] and e["gradcheck"] == {} and 1.0 <= e["values"]["c"] <= 88.0
    oracle, two = e["depth_oracle_train"]["world"], 2.0 / res.n_train
    assert oracle - two <= e["train"] <= oracle * 1.05 + two, (e["train"], oracle)
    assert e["train"] <= min(e["start_train"], e["grid"]["train"])


def test_exponent_boxes_stop_where_the_format_overflows():
    """ESM stores exp(c t): c <= ln 65504 in float16; EVSM stores exp(2 c x) at x = 1: each
    exponent <= ln(65504) / 2; its minimum variance and bleed are the lookup's (no rebuild)."""
    from dsm.tune.moments import tunable
    from dsm.config import read as config
    cfg = config.parse({"experiment": {"name": "x"}, "scene": [{"builtin": "plane"}],
                        "map": {"kind": ["evsm", "esm"], "format": "float16", "esm": {"c": 10.0},
                                "evsm": {"positive": 5.0, "negative": 5.0}}}, "<test>")
    evsm, esm = cfg.map.moments
    box = {p.name: p for p in tunable(evsm, "float16")}
    assert [n for n, p in box.items() if p.rebuild] == ["positive", "negative"]
    assert [n for n, p in box.items() if not p.rebuild] == ["min_variance", "bleed"]
    for n in ("positive", "negative"):
        assert box[n].hi == pytest.approx(math.log(65504.0) / 2, abs=1e-9)
    (c,) = tunable(esm, "float16")
    assert c.rebuild and c.hi == pytest.approx(math.log(65504.0), abs=1e-9)


def test_evsm_tuned_with_its_exponents_is_never_worse_than_its_start_nor_its_grid():
    from dsm.tune.tuner import tune
    res = tune(_cfg(["evsm"], [3], steps=40))
    (e,) = res.moments
    assert e["rebuilt"] and set(e["values"]) == {"positive", "negative", "min_variance", "bleed"}
    assert e["train"] <= min(e["start_train"], e["grid"]["train"])
    assert all(0.5 <= e["values"][k] <= 44.0 for k in ("positive", "negative"))


@pytest.mark.parametrize("map_extra, key", [({"moment_samples": 2}, "map.moment_samples")])
def test_dsm_tune_refuses_supersampled_moments_before_work(map_extra, key):
    from dsm.config.read import coerce
    from dsm.tune import tuner
    from dsm.core.types import ConfigError
    cfg = _cfg(["vsm"], [1])
    cfg["map"].update(map_extra)
    with pytest.raises(ConfigError) as e:
        tuner.parse_tune(coerce(cfg))
    assert e.value.key == key


def test_moment_samples_without_a_pre_filtered_kind_is_refused():
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as e:
        config.parse({"experiment": {"name": "x"}, "scene": [{"builtin": "plane"}], "map": {"moment_samples": 2}},
                     "<test>")
    assert e.value.key == "map.moment_samples"


@pytest.mark.parametrize("kind, table", [("esm", {"c": 0.5}), ("evsm", {"positive": 0.0})])
def test_an_exponent_that_cannot_shadow_is_refused(kind, table):
    """Below ln 2 an ESM never shadows (V = exp(-c (t - z)) >= 1/2 for t - z <= 1): c >= 1 and EVSM's >= 0.5."""
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as e:
        config.parse({"experiment": {"name": "x"}, "scene": [{"builtin": "plane"}],
                      "map": {"kind": [kind], kind: table}}, "<test>")
    assert e.value.key.startswith(f"map.{kind}.")


@pytest.mark.slow
def test_a_tune_of_pre_filtered_maps_alone_resumes(tmp_path):
    from dsm.tune.tuner import tune
    first = tune(_cfg(["vsm"], [1], steps=6), out=tmp_path)
    again = tune(_cfg(["vsm"], [1], steps=6), out=tmp_path, resume=True)
    assert [e["values"] for e in again.moments] == [e["values"] for e in first.moments]


def test_a_learned_map_over_the_best_depth_scheme_is_refused_without_one_and_edge_is_the_default():
    """The edge and residual maps are fitted over the best tuned depth scheme: a tune of pre-filtered
    instances alone has none, and was silently given the Adam map; now it is refused naming the key.
    [tune.bias_map] without fit is the edge map (the fit that beats the best global scheme held out)."""
    from dsm import ConfigError
    from dsm.config.read import coerce
    from dsm.tune.tuner import parse_tune, tune
    cams = [{"position": [2.5, -3.0, 2.0], "target": [0, 0, 0.3]}, {"position": [3.0, 2.5, 2.0], "target": [0, 0, 0.3]},
            {"position": [-2.5, -3.0, 2.0], "target": [0, 0, 0.3], "role": "heldout"}]
    cfg = _cfg(["vsm"], [1])
    cfg["tune"]["camera"] = cams
    cfg["tune"]["bias_map"] = {}
    assert parse_tune(coerce(cfg)).spec.bias_map.fit == "edge"
    for fit in ("edge", "residual"):
        cfg["tune"]["bias_map"] = {"fit": fit}
        with pytest.raises(ConfigError) as e:
            tune(cfg)
        assert e.value.key == "tune.bias_map.fit" and "depth scheme" in str(e.value)
