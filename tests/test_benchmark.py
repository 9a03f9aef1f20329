"""dsm benchmark (dsm-bench-1 to -6): the suites' hash pins, scale normalization, the
far-from-origin axis, the compare rule, the leaderboard's ranking and tie rule, the preset bias
conversion, FLIP, the shaded renders, the scale figure, and one tiny end-to-end run."""
import json

import numpy as np
import pytest

from dsm import cli
from dsm.benchmark import bias_units, compare, ranking, results, suite
from dsm.core.types import Length

import helpers_benchmark_cases
from helpers_benchmark_cases import only_cases

# the suites' identities: changing suite_<n>.toml changes its hash, which makes it a new version
SUITE_1_SHA256 = "15b8554a6f096049e4da44ba45084ae524f5d93f04380a71907185a990a2ba5c"
SUITE_2_SHA256 = "ebd3668f4b3bff1df961afae653c8e91018de253cd2df644be3a1c71884b9cd1"
SUITE_3_SHA256 = "5582fcb3e08f61997b71398424ea90d81b26e8c56d66886b835a18bbdad60677"
SUITE_4_SHA256 = "196f379d78e7a92dd254aabdb5fa6894bb58e74bf7a4d064f6fdeeea94af22b1"
SUITE_5_SHA256 = "ba5710bbaa9e35aa4786570b9dbaf960b6de00a30bd85827c37061d471d57d23"
SUITE_6_SHA256 = "e75a9dd2038cc3f08931d455ecc4224f54996164d9c59fbf144cc2681f454197"


def test_suite_hashes_are_pinned():
    assert suite.suite_sha256(suite.SUITE_FILES["dsm-bench-1"]) == SUITE_1_SHA256
    assert suite.load_suite(suite.SUITE_FILES["dsm-bench-1"])["suite"]["name"] == "dsm-bench-1"
    assert suite.suite_sha256(suite.SUITE_FILES["dsm-bench-2"]) == SUITE_2_SHA256
    assert suite.load_suite(suite.SUITE_FILES["dsm-bench-2"])["suite"]["name"] == "dsm-bench-2"
    assert suite.suite_sha256(suite.SUITE_FILES["dsm-bench-3"]) == SUITE_3_SHA256
    assert suite.load_suite(suite.SUITE_FILES["dsm-bench-3"])["suite"]["name"] == "dsm-bench-3"
    assert suite.suite_sha256(suite.SUITE_FILES["dsm-bench-4"]) == SUITE_4_SHA256
    assert suite.load_suite(suite.SUITE_FILES["dsm-bench-4"])["suite"]["name"] == "dsm-bench-4"
    assert suite.suite_sha256(suite.SUITE_FILES["dsm-bench-5"]) == SUITE_5_SHA256
    assert suite.load_suite(suite.SUITE_FILES["dsm-bench-5"])["suite"]["name"] == "dsm-bench-5"
    # the newest is what dsm benchmark runs by default
    assert suite.LATEST == "dsm-bench-6" and suite.suite_sha256() == SUITE_6_SHA256
    s = suite.load_suite()
    assert s["suite"]["name"] == "dsm-bench-6" and s["flip"]["ppd"] == 67.0


def test_suite_5_is_suite_4_with_the_virtual_maps_under_the_directional_light():
    """dsm-bench-5's cases are dsm-bench-4's (but for their names) plus a virtual config where the scene
    runs the directional light: that light alone, both presets, levels in physical size (100 x factor cm)."""
    s4, s5 = (suite.load_suite(suite.SUITE_FILES[v]) for v in ("dsm-bench-4", "dsm-bench-5"))
    c4, c5 = suite.cases(s4, "default"), suite.cases(s5, "default")
    assert [(c.scene, c.unit, c.offset) for c in c4] == [(c.scene, c.unit, c.offset) for c in c5]
    unnamed = lambda cfg: {**cfg, "experiment": {}}
    factor = {sc["name"]: sc["factor"] for sc in s5["scene"]}
    for a, b in zip(c4, c5):
        assert unnamed(a.config) == unnamed(b.config) and a.virtual is None
        if b.scene == "cbox":                   # spot and point only: no directional light
            assert b.virtual is None
            continue
        v = b.virtual
        assert [t["type"] for t in v["light"]] == ["scene"] and v["scene"] == b.config["scene"]
        assert v["map"] == {"virtual": {"preset": ["ue5", "eevee"], "unit_cm": 100.0 * factor[b.scene]}}
        assert v["scheme"] == [{"name": "normal_offset", "offset": "1 texel"}]
    row = {"cascade_layout": "vsm eevee unit_cm=10", "scheme": "normal_offset", "preset": "", "params": "x"}
    assert results.contender_of(row) == "virtual eevee"


def test_suite_6_is_suite_5_with_the_hybrid_classifier_at_amd_s_settings_and_a_cut_off():
    """dsm-bench-6's cases are dsm-bench-5's (but for their names) plus a hybrid config of every case: the depth
    config with constant at 1 texel and the classifier at the sample's defaults (tileCutOff 0) and at cut-off 8."""
    from dsm.hybrid import classifier
    s5, s6 = (suite.load_suite(suite.SUITE_FILES[v]) for v in ("dsm-bench-5", "dsm-bench-6"))
    c5, c6 = suite.cases(s5, "default"), suite.cases(s6, "default")
    assert [(c.scene, c.unit, c.offset) for c in c5] == [(c.scene, c.unit, c.offset) for c in c6]
    unnamed = lambda cfg: None if cfg is None else {**cfg, "experiment": {}}
    for a, b in zip(c5, c6):
        assert unnamed(a.config) == unnamed(b.config) and unnamed(a.virtual) == unnamed(b.virtual) and a.hybrid is None
        h = b.hybrid
        assert unnamed(h) == {**unnamed(b.config), "scheme": [{"name": "constant", "bias": "1 texel"}],
                              "hybrid": [{"rule": "classifier"}, {"rule": "classifier", "tileCutOff": 8}]}
        assert suite.contender_count(b) == suite.contender_count(a) + 2
    amd = classifier.Params()         # AMD's sample: tileCutOff 0, a 0.25 degree sun, offset 0.002, both flags on
    assert (amd.tileCutOff, amd.blockerOffset, amd.bRejectLitPixels, amd.bUseCascadesForRayT) == (0, 0.002, True, True)
    assert amd.sunSizeLightSpace == pytest.approx(np.tan(np.radians(0.125)), rel=1e-15)
    labels = suite.hybrid_labels(s6)
    assert sorted(labels.values()) == ["hybrid classifier", "hybrid classifier cutoff 8"]
    row = {"hybrid_rule": "classifier", "hybrid_params": next(k for k, v in labels.items() if v.endswith("8"))[1],
           "scheme": "constant", "preset": "", "params": "bias=1 texel"}
    assert results.contender_of(row, None, labels) == "hybrid classifier cutoff 8"


def test_suite_1_still_makes_its_cases_at_the_origin_only():
    s1 = suite.load_suite(suite.SUITE_FILES["dsm-bench-1"])
    cs = suite.cases(s1, "default")
    assert len(cs) == len(s1["scene"]) * 3 and {c.offset for c in cs} == {"0"}
    assert all("translate" not in c.config["scene"][0] for c in cs)


def test_default_size_covers_every_preset_scene_unit_and_light():
    from dsm.schemes.presets import names
    s = suite.load_suite()
    cs = suite.cases(s, "default")
    # every scene at cm, m and km, and at 1e4 and 1e5 (the Cornell box too: an XML scene takes translate)
    assert len(cs) == len(s["scene"]) * (3 + 2)
    assert sorted((c.unit, c.offset) for c in cs if c.scene == "cbox") == [("cm", "0"), ("km", "0"), ("m", "0"),
                                                                           ("m", "1e4"), ("m", "1e5")]
    # dsm-bench-3 kept the box at the origin
    cs3 = suite.cases(suite.load_suite(suite.SUITE_FILES["dsm-bench-3"]), "default")
    assert sorted((c.unit, c.offset) for c in cs3 if c.scene == "cbox") == [("cm", "0"), ("km", "0"), ("m", "0")]
    schemes = cs[0].config["scheme"]
    assert sorted(t["preset"] for t in schemes if "preset" in t) == names()
    assert [t["type"] for t in cs[0].config["light"]] == ["scene", "spot", "point"]
    assert cs[0].config["map"]["cascades"] == 4


def _by(cs, scene, unit, offset="0"):
    return next(c for c in cs if c.scene == scene and c.unit == unit and c.offset == offset)


def test_a_far_case_is_the_metre_case_moved():
    """A far case's config is its origin case's at the far unit but for the translate (and the name)."""
    cs = suite.cases(suite.load_suite(), "default")
    for name in ("bunny", "grazing", "cbox"):
        here = _by(cs, name, "m")
        for offset, translate in (("1e4", [1e4, 5e3, 0.0]), ("1e5", [1e5, 5e4, 0.0])):
            far = _by(cs, name, "m", offset)
            assert far.config["scene"][0].pop("translate") == translate and far.translate == tuple(translate)
            assert far.config["experiment"].pop("name") == f"dsm-bench-6-{name}-m-at-{offset}"
            assert {**here.config, "experiment": {}} == {**far.config, "experiment": {}}
    assert {c.unit for c in cs if c.offset != "0"} == {"m"}


def test_far_lights_move_with_the_scene():
    """At 1e4 the loaded point light sits where the origin's does plus the translate (float64)."""
    cs = suite.cases(suite.load_suite(), "default")
    sd0, _, _, cfg0 = _loaded(_by(cs, "bunny", "m"))
    sd1, lo1, hi1, cfg1 = _loaded(_by(cs, "bunny", "m", "1e4"))
    p0 = [l.position for l in sd0.lights_for(cfg0.lights) if l.type == "point"][0]
    p1 = [l.position for l in sd1.lights_for(cfg1.lights) if l.type == "point"][0]
    np.testing.assert_allclose(np.asarray(p1) - np.asarray(p0), [1e4, 5e3, 0.0], rtol=0, atol=1e-9)
    assert lo1[0] > 9e3 and hi1[0] < 1.1e4


def test_configs_scale_by_the_unit_and_factor():
    cs = suite.cases(suite.load_suite(), "default")
    for name, factor in (("bunny", 1.0), ("bunny_watertight", 0.1), ("grazing", 1.0)):
        assert _by(cs, name, "cm").scale == pytest.approx(100 * factor)
        assert _by(cs, name, "m").scale == pytest.approx(factor)
        assert _by(cs, name, "km").scale == pytest.approx(0.001 * factor)
    # a mesh's spot is given in native units: metres about the centre / factor (by hand: (0.013 - 0.25) / 0.1)
    spot = _by(cs, "bunny_watertight", "m").config["light"][1]
    assert spot["position"][0] == pytest.approx(-2.37)


def _loaded(case):
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    from dsm.config.read import parse
    from dsm.scenes.load import load
    cfg = parse(case.config, "<benchmark>")
    sd = load(cfg.scenes[0], (16, 16))
    mesh = next(s for s in sd.scene.shapes() if s.id() == "mesh")
    lo, hi = np.array(mesh.bbox().min, float), np.array(mesh.bbox().max, float)
    return sd, lo, hi, cfg


def test_a_scene_in_cm_is_100_times_the_metre_one():
    cs = suite.cases(suite.load_suite(), "default")
    sd_m, lo_m, hi_m, cfg_m = _loaded(_by(cs, "bunny_watertight", "m"))
    sd_cm, lo_cm, hi_cm, cfg_cm = _loaded(_by(cs, "bunny_watertight", "cm"))
    np.testing.assert_allclose(hi_cm - lo_cm, 100 * (hi_m - lo_m), rtol=1e-5)
    # normalized to the Stanford bunny's real height (y up): 0.154 m, the scan's (measured on mitsuba_bunny.ply)
    assert float(hi_m[1] - lo_m[1]) == pytest.approx(0.154, abs=0.002)
    # the lights move with it
    p_m = [l.position for l in sd_m.lights_for(cfg_m.lights) if l.type == "point"][0]
    p_cm = [l.position for l in sd_cm.lights_for(cfg_cm.lights) if l.type == "point"][0]
    np.testing.assert_allclose(np.asarray(p_cm), 100 * np.asarray(p_m), rtol=1e-9)


def _rec(contender, unit, n_acne, n_peterpan=0, n_receivers=1000, scene="s", light="directional", offset="0"):
    return {"scene": scene, "unit": unit, "offset": offset, "light": light, "contender": contender, "n_receivers": n_receivers,
            "n_acne": n_acne, "n_peterpan": n_peterpan, "acne_rate": n_acne / n_receivers,
            "peterpan_rate": 0.0, "error_rate": (n_acne + n_peterpan) / n_receivers, "texel_size": 0.01,
            "build_ms": 1.0, "lookup_ms": 1.0}


def test_compare_tells_a_change_from_a_tie():
    # 1000 receivers: the tolerance is max(1, 2) = 2; 5000 receivers: max(5, 2) = 5
    a = {"suite": "dsm-bench-1", "suite_sha256": "x", "cases": [
        _rec("p", "m", 10), _rec("q", "m", 10), _rec("r", "m", 100, n_receivers=5000),
        _rec("t", "m", 100, n_receivers=5000), _rec("gone", "m", 0)]}
    b = {"suite": "dsm-bench-1", "suite_sha256": "x", "cases": [
        _rec("p", "m", 12), _rec("q", "m", 13), _rec("r", "m", 104, n_receivers=5000),
        _rec("t", "m", 94, n_receivers=5000), _rec("new", "m", 0)]}
    diff = compare.compare(a, b)
    assert [c["case"][4] for c in diff["changed"]] == ["q", "t"]     # moves 3 > 2 and 6 > 5
    assert diff["changed"][0]["moves"] == [["n_acne", 10, 13]]
    assert diff["n_tied"] == 2                                         # p (2 <= 2) and r (4 <= 5)
    assert diff["added"] == [["s", "m", "0", "directional", "new"]]
    assert diff["removed"] == [["s", "m", "0", "directional", "gone"]]
    assert diff["same_suite"]
    # a dsm-bench-1 record has no offset: it sits at the origin
    v1 = {k: v for k, v in _rec("p", "m", 10).items() if k != "offset"}
    assert compare.case_key(v1) == ("s", "m", "0", "directional", "p")


def test_compare_tells_flip_and_flicker_changes_from_ties():
    """FLIP moves beyond 0.001 and flicker rates beyond 0.002 are changes; smaller ones (and a FLIP
    missing on one side) are ties; a flicker record in one file only is added or removed."""
    fa, fb = _rec("p", "m", 10), _rec("p", "m", 10)
    fa["flip"], fb["flip"] = 0.0500, 0.0515            # moved 0.0015 > 0.001
    ta, tb = _rec("q", "m", 10), _rec("q", "m", 10)
    ta["flip"], tb["flip"] = 0.0500, 0.0509            # 0.0009: a tie
    fl = lambda c, rate: {"scene": "g", "unit": "m", "offset": "0", "light": "directional", "contender": c,
                          "flicker_rate": rate}
    a = {"suite": "dsm-bench-4", "suite_sha256": "x", "cases": [fa, ta],
         "flicker": [fl("p", 0.100), fl("q", 0.100), fl("gone", 0.0)]}
    b = {"suite": "dsm-bench-4", "suite_sha256": "x", "cases": [fb, tb],
         "flicker": [fl("p", 0.1025), fl("q", 0.1015), fl("new", 0.0)]}
    diff = compare.compare(a, b)
    assert [c["case"][4] for c in diff["changed"]] == ["p"] and diff["changed"][0]["moves"] == [["flip", 0.05, 0.0515]]
    assert diff["n_tied"] == 1
    f = diff["flicker"]
    assert [c["case"][4] for c in f["changed"]] == ["p"] and f["n_tied"] == 1      # 0.0025 > 0.002; 0.0015 ties
    assert f["added"] == [["g", "m", "0", "directional", "new"]] and f["removed"] == [["g", "m", "0", "directional", "gone"]]
    assert "flicker: 1 records changed, 1 tied, 1 added, 1 removed" in compare.text(diff)


def test_compare_command_writes_its_files(tmp_path):
    a = {"suite": "dsm-bench-1", "suite_sha256": "x", "cases": [_rec("p", "m", 10)]}
    b = {"suite": "dsm-bench-1", "suite_sha256": "y", "cases": [_rec("p", "m", 20)]}
    (tmp_path / "a.json").write_text(json.dumps(a))
    (tmp_path / "b.json").write_text(json.dumps(b))
    assert cli.main(["benchmark", "--compare", str(tmp_path / "a.json"), str(tmp_path / "b.json"),
                     "--out", str(tmp_path / "cmp")]) == 0
    diff = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert not diff["same_suite"] and diff["changed"][0]["moves"] == [["n_acne", 10, 20]]
    assert "different suite hashes" in (tmp_path / "cmp" / "compare.txt").read_text()


def test_ranking_orders_and_ties_by_hand():
    # mean error rates by hand: c 0.05, a (0.10 + 0.20) / 2 = 0.15, b (0.1504 + 0.1500) / 2 = 0.1502,
    # d 0.30. a and b differ by 0.0002 < 0.001: a tie, sharing rank 2 (by name); d is 4th.
    doc = {"cases": [_rec("a", "cm", 100), _rec("a", "m", 200), _rec("b", "cm", 1504, n_receivers=10000),
                     _rec("b", "m", 1500, n_receivers=10000), _rec("c", "cm", 50), _rec("c", "m", 50),
                     _rec("d", "cm", 300), _rec("d", "m", 300),
                     {"scene": "s", "unit": "m", "light": "directional", "contender": "oracle", "n_receivers": 1000,
                      "world_objective": 0.02, "texel_objective": 0.03, "per_texel_objective": 0.0}]}
    ranked = ranking.ranking(doc)
    assert [(r["rank"], r["contender"]) for r in ranked] == [(1, "c"), (2, "a"), (2, "b"), (4, "d")]
    assert ranked[1]["spread"] == pytest.approx(0.1)          # a: 0.20 - 0.10 across cm and m
    # smallest spread: c and d (0); c has the lower score
    assert ranking.most_scale_robust(ranked)["contender"] == "c"
    assert ranking.most_scale_robust(ranked, among={"bevy"}) is None      # no such contender: no answer, no error
    assert ranking.oracle_floor(doc)["world_objective"] == pytest.approx(0.02)


def test_bias_conversion_to_world_and_texels():
    assert bias_units.converted(Length(0.02, "world"), 0.001) == pytest.approx((0.02, 20.0))
    assert bias_units.converted(Length(2.0, "texel"), 0.5) == pytest.approx((1.0, 2.0))
    assert bias_units.converted(Length(0.005, "range"), 0.5) == (None, None)
    assert bias_units.scale_free("godot") and not bias_units.scale_free("bevy")


@pytest.fixture(scope="module")
def test_run(tmp_path_factory):
    """dsm benchmark at the test size, once for this module: (its folder, results.json)."""
    out = tmp_path_factory.mktemp("bench")
    assert cli.main(["benchmark", "--out", str(out), "--size", "test"]) == 0
    return out, json.loads((out / "results.json").read_text())


@pytest.mark.slow
def test_benchmark_end_to_end_at_test_size(test_run):
    out, doc = test_run
    assert doc["suite"] == "dsm-bench-6" and doc["suite_sha256"] == SUITE_6_SHA256 and doc["size"] == "test"
    assert doc["machine"]["cores"] >= 1 and doc["versions"]["dsm_git_commit"]
    assert doc["far_unit"] == "m" and doc["flip_ppd"] == 67.0
    # 2 scenes x (2 units + 2 offsets at m) x 1 light x (3 contenders + the tuned one + the oracle
    # + 2 pre-filtered kinds at their defaults + their presets: vsm three, msm mjp + 2 virtual maps
    # + 2 hybrid classifiers)
    assert len(doc["cases"]) == 104
    # what ran is what --help counts for the size (tests/test_benchmark_size.py counts it from the TOML)
    ran = {(r["scene"], r["unit"], r["offset"]) for r in doc["cases"]}, {r["contender"] for r in doc["cases"]} - {"oracle"}
    summary = suite.size_summary(suite.load_suite(), "test")
    assert summary.startswith(f"{len(ran[0])} cases (") and f", {len(ran[1])} contenders," in summary
    recs = {(r["scene"], r["unit"], r["offset"], r["contender"]): r for r in doc["cases"]}
    for r in doc["cases"]:
        if r["contender"] != "oracle":
            assert r["error_rate"] == pytest.approx((r["n_acne"] + r["n_peterpan"]) / r["n_receivers"])
            assert 0.0 <= r["flip"] <= 1.0
    # the texel width follows the unit: 100 times wider in cm (the map is fitted to the scene)
    assert recs[("bunny", "cm", "0", "bevy")]["texel_size"] == pytest.approx(
        100 * recs[("bunny", "m", "0", "bevy")]["texel_size"], rel=1e-3)
    # a virtual map's levels are physical: the same receivers and counts in cm and m, texels 100 times wider
    for name in ("virtual ue5", "virtual eevee"):
        cm, m = recs[("bunny", "cm", "0", name)], recs[("bunny", "m", "0", name)]
        assert cm["texel_size"] == pytest.approx(100 * m["texel_size"], rel=1e-5)
        assert (cm["n_receivers"], cm["n_acne"], cm["n_peterpan"]) == (m["n_receivers"], m["n_acne"], m["n_peterpan"])
    page = (out / "leaderboard.html").read_text()
    assert "Ranking" in page and "Oracle floor" in page and "three" in page and "http" not in page
    assert "function sortBy" in page and 'class="sortable filtered"' in page   # report.html's header sort
    # the error at each offset: the offset table's columns (the ranking keeps the far change)
    assert "FLIP" in page and "<th data-type=num>1e5</th>" in page and "far change" in page and "src=scale.png" in page


@pytest.mark.slow
def test_far_cases_keep_the_exact_side_and_lose_only_the_map_s_precision(test_run):
    """Where the scene sits moves no exact count: receivers and V*'s shadowed receivers are the
    origin's at 1e4 and 1e5, every contender. The errors may move, and only in cases the map's
    float32 limits (a texel under 64 float32 steps, design.md's far-from-origin section): measured
    (test size, bunny at m): receiver_plane's acne 21 at the origin, 135 at 1e4, 150 at 1e5."""
    from dsm.maps.headroom import FEW_STEPS
    _, doc = test_run
    recs = {(r["scene"], r["unit"], r["offset"], r["contender"]): r for r in doc["cases"]}
    moved = 0
    for (scene, unit, offset, who), r in recs.items():
        if offset == "0":
            continue
        here = recs[(scene, unit, "0", who)]
        assert r["n_receivers"] == here["n_receivers"]
        if who == "oracle":
            continue
        assert r["n_gt_shadowed"] == here["n_gt_shadowed"]
        if compare.case_changes(here, r):
            moved += 1
            assert r["texel_f32_steps"] < FEW_STEPS <= here["texel_f32_steps"]
    assert moved > 0                     # the axis measures something at this size
    # the ranking's far columns, by a second computation in numpy from the records
    ranked = {r["contender"]: r for r in ranking.ranking(doc)}
    for who in ("bevy", "three", "receiver_plane"):
        far = [recs[(s, "m", "1e5", who)]["error_rate"] - recs[(s, "m", "0", who)]["error_rate"]
               for s in ("bunny", "grazing")]
        assert ranked[who]["far_change"] == pytest.approx(float(np.mean(far)), abs=1e-15)
        assert ranked[who]["far"]["1e4"] == pytest.approx(
            float(np.mean([recs[(s, "m", "1e4", who)]["error_rate"] for s in ("bunny", "grazing")])), abs=1e-15)


@pytest.mark.slow
def test_far_numbers_come_back_in_camera_relative_precision(test_run):
    """The far case run as an engine with camera-relative positions counts what the origin
    counts, contender by contender: the far axis's moves are the map's float32, nothing else."""
    import dsm
    _, doc = test_run
    case = _by(suite.cases(suite.load_suite(), "test"), "grazing", "m", "1e4")
    case.config["scene"][0]["precision"] = "camera_relative"
    res = dsm.run(case.config, report=False)
    origin = {(r["contender"]): r for r in doc["cases"] if r["scene"] == "grazing" and r["unit"] == "m"
              and r["offset"] == "0"}
    for row in res.rows:
        here = origin[results.contender_of(row, suite.tuned_labels(suite.load_suite()))]
        assert (row["n_receivers"], row["n_acne"], row["n_peterpan"]) == \
            (here["n_receivers"], here["n_acne"], here["n_peterpan"])


@pytest.mark.slow
def test_the_scale_figure_and_tables_hold_the_results_numbers(test_run):
    """scale.png is beside the page, draws a curve per contender (and the oracle) with the
    numbers the page's tables print, which are the records' means (numpy, float64)."""
    from PIL import Image
    import re
    from dsm.benchmark import figure
    out, doc = test_run
    with Image.open(out / "scale.png") as im:
        assert im.format == "PNG" and im.width > 400 and im.height > 150
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3).astype(int)
    who = ["bevy", "hybrid classifier", "hybrid classifier cutoff 8", "msm box:5", "msm mjp box:5", "oracle",
           "receiver_plane", "three", "tuned_normal_angle", "virtual eevee", "virtual ue5", "vsm box:5",
           "vsm three box:5"]
    def by_numpy(keep):
        value = lambda r: r["per_texel_objective"] if r["contender"] == "oracle" else r["error_rate"]
        return [float(np.mean(np.array([value(r) for r in doc["cases"] if r["contender"] == c and keep(r)],
                                       np.float64))) for c in who]
    data = figure.series(doc)
    assert data["unit"][0] == ["cm", "m"] and data["offset"][0] == ["0", "1e4", "1e5"]
    for u_i, u in enumerate(["cm", "m"]):
        expect = by_numpy(lambda r, u=u: r["unit"] == u and r["offset"] == "0")
        np.testing.assert_allclose([data["unit"][1][c][u_i] for c in who], expect, rtol=1e-12, atol=1e-15)
    for o_i, o in enumerate(["0", "1e4", "1e5"]):
        expect = by_numpy(lambda r, o=o: r["unit"] == "m" and r["offset"] == o)
        np.testing.assert_allclose([data["offset"][1][c][o_i] for c in who], expect, rtol=1e-12, atol=1e-15)
    fig = figure.draw(data, "m")
    lines = {(ax.get_xlabel()[:6], ln.get_label()): list(ln.get_ydata()) for ax in fig.axes for ln in ax.get_lines()}
    assert sorted(label for kind, label in lines if kind == "scene ") == who
    assert lines[("offset", "receiver_plane")] == data["offset"][1]["receiver_plane"]
    from matplotlib.colors import to_rgb
    for ln in fig.axes[0].get_lines():       # each contender's curve is drawn in the PNG, in its colour
        rgb = np.round(np.array(to_rgb(ln.get_color())) * 255).astype(int)
        assert (np.abs(pixels - rgb).max(1) <= 8).sum() > 20, ln.get_label()
    # the page's offset table: a row per contender, the same numbers
    page = (out / "leaderboard.html").read_text()
    section = page[page.index("Error rate against the offset"):]
    row = re.search(r"<tr[^>]*><td>receiver_plane</td>(.*?)</tr>", section).group(1)
    cells = [float(v) for v in re.findall(r'data-v="([^"]*)"', row)]
    assert cells == data["offset"][1]["receiver_plane"]


def test_a_second_benchmark_into_the_same_folder_is_refused_and_keeps_the_first(tmp_path, capsys):
    """results.json of an earlier run is never overwritten without --force: one line naming --out
    and --force, exit 2, the file as it was."""
    from dsm.cli import main
    out = tmp_path / "bm"
    out.mkdir()
    (out / "results.json").write_text('{"kept": true}')
    assert main(["benchmark", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and "--force" in err[0] and "results.json" in err[0]
    assert (out / "results.json").read_text() == '{"kept": true}'


def test_flip_of_identical_renders_is_zero_and_a_pair_is_flip_evaluator_s():
    import flip_evaluator
    from dsm.benchmark import perceptual
    rng = np.random.default_rng(3)
    a, b = rng.random((24, 32)), rng.random((24, 32))
    assert perceptual.mean_flip(a, a, 67.0) == 0.0
    rgb = lambda g: np.stack([g, g, g], axis=2).astype(np.float32)
    expect = flip_evaluator.evaluate(rgb(a), rgb(b), "LDR", parameters={"ppd": 67.0})[1]
    assert perceptual.mean_flip(a, b, 67.0) == pytest.approx(expect, rel=1e-6) and expect > 0.05
    # the pinned pixels per degree is what FLIP is told
    assert perceptual.mean_flip(a, b, 20.0) == pytest.approx(
        flip_evaluator.evaluate(rgb(a), rgb(b), "LDR", parameters={"ppd": 20.0})[1], rel=1e-6)
    assert perceptual.mean_flip(a, b, 20.0) != pytest.approx(expect, rel=1e-3)


def _plane_box_spot_at_1e5():
    """plane_box at 1e5 under the spot at the default size, one contender: its map's view leaves out
    one of the light's receivers (measured), which the renders must leave out too."""
    case = _by(suite.cases(suite.load_suite(), "default"), "plane_box", "m", "1e5")
    cfg = {**case.config, "light": [t for t in case.config["light"] if t["type"] == "spot"],
           "scheme": [{"preset": "bevy"}], "map": {"resolution": case.config["map"]["resolution"]}}
    return suite.Case(case.scene, case.unit, case.scale, cfg, case.offset, case.translate)


@pytest.mark.parametrize("which", [pytest.param("bunny_far", marks=pytest.mark.slow), "plane_box_spot_far"])
def test_the_renders_are_the_run_s_shadow_image_and_its_exact_twin(tmp_path, which):
    """A far case run into a folder: the benchmark's render under V is the run's shadow PNG, byte for
    byte (8-bit); the exact render differs from it only on the case's errors (brighter on acne,
    darker on peter-panning); the case's FLIP is flip-evaluator's on these two arrays, evaluated once per
    distinct pair of renders, and its per-pixel map (kept for the case images) flip-evaluator's map."""
    import dsm
    import flip_evaluator
    from PIL import Image
    from dsm.benchmark import render, results
    from dsm.report.figures import image_paths, shade_image
    from dsm.truth import metrics
    case = _by(suite.cases(suite.load_suite(), "test"), "bunny", "m", "1e4") if which == "bunny_far" \
        else _plane_box_spot_at_1e5()
    res = dsm.run(case.config, out=tmp_path / "run", report=False)
    if which == "plane_box_spot_far":      # the view's subset is there: fewer case receivers than the light has
        setups = render.light_setups(case.config)
        assert res.rows[0]["n_receivers"] < len(setups[(res.rows[0]["scene"], res.rows[0]["light"])][1].pixels)
    setups = render.light_setups(case.config)
    known, maps = {}, {}
    flips = results.case_flips(case, res, 67.0, known=known, maps=maps)
    pairs = set()
    for row in res.rows:
        shadowed, exact = render.case_renders(setups, row, res.images[row["case"]])
        pairs.add((exact.tobytes(), shadowed.tobytes()))
        with Image.open(res.out / image_paths(row)[1]) as im:
            assert np.array_equal(shade_image(shadowed), np.asarray(im))
        c = metrics.base_class(res.images[row["case"]])
        acne, peter = c == metrics.ACNE, c == metrics.PETERPAN
        assert np.array_equal(shadowed[~(acne | peter)], exact[~(acne | peter)])
        assert (exact[acne] >= shadowed[acne]).all() and (exact[peter] <= shadowed[peter]).all()
        assert (exact != shadowed).sum() > 0 or row["n_acne"] + row["n_peterpan"] == 0
        rgb = lambda g: np.repeat(np.clip(g, 0, 1)[..., None], 3, axis=2).astype(np.float32)
        error, mean, _ = flip_evaluator.evaluate(rgb(exact), rgb(shadowed), "LDR", applyMagma=False,
                                                 parameters={"ppd": 67.0})
        assert flips[row["case"]] == pytest.approx(mean, rel=1e-6)
        # the kept per-pixel map (the case images' FLIP) is flip-evaluator's, and its mean the row's
        assert maps[row["case"]].shape == exact.shape and np.allclose(maps[row["case"]], error[..., 0], atol=1e-6)
        assert maps[row["case"]].astype(np.float64).mean() == pytest.approx(flips[row["case"]], abs=1e-5)
    assert len(known) == len(pairs)          # one FLIP evaluation per distinct pair of renders


def test_the_cornell_box_is_in_millimetres_and_on_the_far_axis():
    """Its scale is factor x unit (0.001 x 100, x 1, x 0.001); at metres the box is 0.556 m wide (the
    file's 556 units, its Cornell-data millimetres); only spot and point, both inside the box; at 1e4 its
    bounds are the origin's plus the translate."""
    import mitsuba as mi
    from dsm.config.read import parse
    from dsm.scenes.load import load
    mi.set_variant("llvm_ad_rgb")
    every = [c for c in suite.cases(suite.load_suite(), "default") if c.scene == "cbox"]
    cs = {c.unit: c for c in every if c.offset == "0"}
    assert sorted(cs) == ["cm", "km", "m"]
    for unit, scale in (("cm", 0.1), ("m", 0.001), ("km", 1e-6)):
        assert cs[unit].scale == pytest.approx(scale, rel=1e-12) and cs[unit].config["scene"][0]["scale"] == cs[unit].scale
    cfg = parse(cs["m"].config, "<benchmark>")
    sd = load(cfg.scenes[0], (16, 16))
    lo, hi = np.array(sd.scene.bbox().min, float), np.array(sd.scene.bbox().max, float)
    np.testing.assert_allclose(hi - lo, [0.556, 0.5488, 0.5592], rtol=1e-5)
    lights = sd.lights_for(cfg.lights)
    assert [l.type for l in lights] == ["spot", "point"] and "cascades" not in cs["m"].config["map"]
    for l in lights:
        assert (lo < np.asarray(l.position)).all() and (np.asarray(l.position) < hi).all()
    far = next(c for c in every if c.offset == "1e4")
    sd_far = load(parse(far.config, "<benchmark>").scenes[0], (16, 16))
    np.testing.assert_allclose(np.array(sd_far.scene.bbox().min, float), lo + [1e4, 5e3, 0.0], rtol=0, atol=2e-3)
    assert sd_far.centre is not None            # traced in the frame centred on the box


@pytest.mark.slow
def test_the_cornell_box_counts_alike_in_cm_and_m_for_scale_free_contenders():
    """The kit's scale independence on the XML scene: every preset whose terms are in texels or depth
    range, the texel-unit schemes and a pre-filtered kind (normalized depth) count the same receivers,
    acne and peter-panning at cm as at m (measured at 32^2, map 256: all of them equal; bevy's world
    bias and dual's back-face pass move by a receiver or more)."""
    import dsm
    from dsm.schemes.presets import names
    free = [n for n in names() if bias_units.scale_free(n)]
    assert len(free) >= 4
    cs = {c.unit: c for c in suite.cases(suite.load_suite(), "default") if c.scene == "cbox" and c.offset == "0"}
    counts = {}
    for unit in ("cm", "m"):
        c = cs[unit]
        small = {"camera": {"resolution": [32, 32]}, "map": {**c.config["map"], "resolution": 256}}
        cfg = {**c.config, **small, "scheme": suite.contender_tables(
            suite.load_suite(), free + ["constant", "normal_offset", "receiver_plane"])}
        kinds_off = ("evsm", "msm", "vsm")          # vsm at its defaults: its presets' tables left out too
        pre_map = {k: v for k, v in c.prefiltered["map"].items() if k not in kinds_off}
        pre = {**c.prefiltered, **small, "map": {**pre_map, "resolution": 256, "kind": ["vsm"]}}
        rows = dsm.run(cfg, report=False).rows + dsm.run(pre, report=False).rows
        counts[unit] = {(r["light"], results.contender_of(r)): (r["n_receivers"], r["n_acne"], r["n_peterpan"])
                        for r in rows}
    assert len(counts["m"]) == 2 * (len(free) + 3 + 1)
    assert counts["cm"] == counts["m"]
    assert min(n for n, _, _ in counts["m"].values()) > 400


@pytest.mark.slow
def test_prefiltered_contenders_carry_leaks_and_their_pooled_leak_rate(test_run):
    """Each pre-filtered record has n_leak <= n_peterpan and leak_rate = n_leak / n_gt_shadowed; the
    leaderboard's leak rate is sum n_leak / sum n_gt_shadowed over the origin cases (numpy, int64);
    a depth contender has none; the page prints it."""
    out, doc = test_run
    pre = [r for r in doc["cases"] if r.get("map_kind") in ("vsm", "msm")]
    assert {r["contender"] for r in pre} == {"vsm box:5", "vsm three box:5", "msm box:5", "msm mjp box:5"}
    assert len(pre) == 32
    for r in pre:
        assert 0 <= r["n_leak"] <= r["n_peterpan"] and r["leak_rate"] == pytest.approx(r["n_leak"] / r["n_gt_shadowed"])
        assert "texel_f32_steps" in r and 0.0 <= r["flip"] <= 1.0
    ranked = {r["contender"]: r for r in ranking.ranking(doc)}
    for who in ("vsm box:5", "vsm three box:5", "msm box:5", "msm mjp box:5"):
        here = [r for r in pre if r["contender"] == who and r["offset"] == "0"]
        expect = np.sum(np.array([r["n_leak"] for r in here], np.int64)) / \
            np.sum(np.array([r["n_gt_shadowed"] for r in here], np.int64))
        assert ranked[who]["leak"] == pytest.approx(float(expect), abs=1e-15)
    assert ranked["bevy"]["leak"] is None and not any("n_leak" in r for r in doc["cases"] if "map_kind" not in r)
    assert sum(r["n_leak"] for r in pre) > 0                # leaking is measured here, not all zero
    page = (out / "leaderboard.html").read_text()
    best = min(("vsm box:5", "vsm three box:5", "msm box:5", "msm mjp box:5"),
               key=lambda c: (ranked[c]["error"], c))                               # the lowest error, not the name
    assert "leak rate" in page and f"Best pre-filtered map: {best} (" in page


def test_the_tuned_contender_is_the_tune_s_result_exactly():
    """suite_3's tuned_normal_angle holds the values of the tune it names (dsm/benchmark/tune_3.json,
    the stored tune.json): the same scheme, numbers and units, and it was that tune's best scheme."""
    from pathlib import Path
    from dsm.config.read import parse_scheme
    from dsm.schemes import ALL, PRESETS
    from dsm.core.types import Length
    stored = json.loads((Path(suite.__file__).with_name("tune_3.json")).read_text())
    best = min(stored["schemes"], key=lambda e: e["train"]["objective"])
    t = suite.load_suite()["contenders"]["tuned"]["tuned_normal_angle"]
    assert best["scheme"] == t["name"] == "normal_angle"
    spec, = parse_scheme(dict(t), "<suite>", "t", ALL, PRESETS)
    for k, v in best["values"].items():
        assert getattr(spec.params, k) == Length(v, best["units"][k])       # exactly: no rounding on the way
    assert suite.tuned_labels(suite.load_suite()) == {("normal_angle", spec.label): "tuned_normal_angle"}


@pytest.mark.slow
def test_the_tuned_contender_runs_under_its_own_name(test_run):
    out, doc = test_run
    tuned = [r for r in doc["cases"] if r["contender"] == "tuned_normal_angle"]
    assert len(tuned) == 8 and {r["params"] for r in tuned} == {"bias=1.21429 texel max=12 texel"}
    assert doc["tuned"]["tuned_normal_angle"]["bias"] == "1.2142857142857142 texel"
    assert "Best tuned scheme: tuned_normal_angle" in (out / "leaderboard.html").read_text()


@pytest.mark.slow
def test_flicker_is_frames_csv_s_recomputed(test_run):
    """Each flicker record's flicker_rate is the mean over frame pairs of n_flicker / n_pairs_eligible
    of its case's rows in its frames.csv (numpy, float64; the first frame has no pair); the leaderboard's
    flicker is the mean of a contender's records; every contender, pre-filtered ones included, has one per
    light."""
    import csv
    out, doc = test_run
    fl = doc["flicker"]
    every = {"bevy", "three", "receiver_plane", "tuned_normal_angle", "vsm box:5", "vsm three box:5", "msm box:5",
             "msm mjp box:5"}
    assert {r["contender"] for r in fl} == every and len(fl) == 8           # grazing at m, the directional light
    assert all(r["scene"] == "grazing" and r["unit"] == "m" and r["frames"] == 6 for r in fl)
    for r in fl:
        with open(out / r["frames_csv"]) as f:
            frames = [x for x in csv.DictReader(f) if x["case"] == r["case"]]
        assert [int(x["frame"]) for x in frames] == list(range(6))
        pairs = [(int(x["n_flicker"]), int(x["n_pairs_eligible"])) for x in frames[1:]]
        assert all(e > 0 for _, e in pairs)
        expect = float(np.mean(np.array([n / e for n, e in pairs], np.float64)))
        assert r["flicker_rate"] == pytest.approx(expect, rel=1e-12, abs=1e-15)
    ranked = {r["contender"]: r for r in ranking.ranking(doc)}
    for r in fl:
        assert ranked[r["contender"]]["flicker"] == pytest.approx(r["flicker_rate"], abs=1e-15)
    page = (out / "leaderboard.html").read_text()
    assert "no oracle floor" in page and "while the sun turns 2 degrees" in page and "every contender" in page


# the cluster test's cases: both scenes, the bunny's mesh file read by the workers far from the origin
# (the exact frame), the grazing plane in cm (the unit's scale); every kind of config runs in each
# (depth, pre-filtered, virtual, hybrid), so every kind of map group is a Ray task
RAY_CASES = (("bunny", "m", "1e5"), ("grazing", "cm", "0"))


@pytest.mark.slow
def test_the_benchmark_on_a_local_ray_cluster_counts_as_here(test_run, tmp_path, monkeypatch):
    """dsm benchmark --cluster local: every case's counts those of the run here (the map groups are
    Ray tasks; the motion runs stay here), and results.json says where it ran. Two of the test
    size's eight cases (RAY_CASES): the other six add time, not another kind of task."""
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'dsm[cluster]')")
    _, here = test_run
    monkeypatch.setattr(results, "cases", only_cases(RAY_CASES))
    try:
        assert cli.main(["benchmark", "--out", str(tmp_path), "--size", "test", "--cluster", "local"]) == 0
    finally:
        ray.shutdown()
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["backend"] == {"name": "ray", "address": "local"} and here["backend"] == {"name": "local"}
    key = lambda r: (r["scene"], r["unit"], r["offset"], r["light"], r["contender"], r.get("params", ""))
    counts = ("n_receivers", "n_acne", "n_peterpan", "n_gt_shadowed", "flip")     # FLIP from the PNGs read back
    want = {key(r): tuple(r.get(k) for k in counts) for r in here["cases"] if key(r)[:3] in RAY_CASES}
    got = {key(r): tuple(r.get(k) for k in counts) for r in doc["cases"]}
    assert got == want and len(got) == len(doc["cases"]) == 13 * len(RAY_CASES)


# the interrupted run's cases: three of the grazing scene's (its cheapest), the second with the motion
# run whose flicker records a resumed run must read back from the kept case
RESUME_CASES = (("grazing", "cm", "0"), ("grazing", "m", "0"), ("grazing", "m", "1e4"))


def _suite_process(out, *flags, signal_after=(0, "none"), keys=RESUME_CASES):
    """``dsm benchmark --out OUT`` at the test size in a process of its own, on the cases ``keys``;
    ``signal_after``: (n, signal name) sends the process that signal itself once it has kept its n-th case."""
    import subprocess
    import sys
    args = ["benchmark", "--out", str(out), "--size", "test", *flags]
    cmd = [sys.executable, helpers_benchmark_cases.__file__, str(signal_after[0]), signal_after[1], json.dumps(keys),
           *args]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _counts(doc, keys) -> dict:
    """Every count, FLIP and flicker measure of ``doc``'s records of the cases ``keys``, by record."""
    key = lambda r: (r["scene"], r["unit"], r["offset"], r["light"], r["contender"], r.get("params", ""))
    cols = ("n_receivers", "n_acne", "n_peterpan", "n_gt_shadowed", "flip", "n_leak", "per_texel_objective")
    cases = {key(r): tuple(r.get(k) for k in cols) for r in doc["cases"] if key(r)[:3] in keys}
    flick = {key(r): (r["flicker_rate"], r["flicker_ever"], r["flicker_magnitude"]) for r in doc["flicker"]
             if key(r)[:3] in keys}
    return {"cases": cases, "flicker": flick, "n": (len(cases), len(flick))}


@pytest.mark.slow
def test_ctrl_c_and_kill_keep_finished_cases_and_resume_counts_as_uninterrupted(test_run, tmp_path, monkeypatch,
                                                                                capsys):
    """Ctrl-C once the first case is kept: exit 130, a line saying what is kept and how to go on.
    --resume, killed (SIGKILL) once another case is kept, then --resume to the end: every count,
    FLIP and flicker rate that of the uninterrupted run, the kept cases not run again, and every
    case's class image and FLIP map the same bytes as the uninterrupted run's. Three of the test
    size's cases (RESUME_CASES), one kept by each run. The two runs a signal stops are processes of
    their own (a real SIGINT, a real SIGKILL); the last resume, which no signal stops, runs in this one."""
    import signal
    whole_out, whole = test_run
    out, n = tmp_path / "bm", len(RESUME_CASES)
    proc = _suite_process(out, signal_after=(1, "SIGINT"))
    _, err = proc.communicate(timeout=900)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    kept = len(list((out / "cases").glob("[0-9]*.json")))
    assert kept == 1 and not (out / "results.json").exists()
    assert cli.main(["benchmark", "--out", str(out)]) == 2        # a plain run into it is refused: it names --resume
    proc = _suite_process(out, "--resume", signal_after=(1, "SIGKILL"))
    proc.communicate(timeout=900)
    assert proc.returncode == -signal.SIGKILL
    assert len(list((out / "cases").glob("[0-9]*.json"))) == kept + 1
    kept += 1
    monkeypatch.setattr(results, "cases", only_cases(RESUME_CASES))
    capsys.readouterr()
    rc = cli.main(["benchmark", "--out", str(out), "--size", "test", "--resume"])
    stdout, err = capsys.readouterr()
    assert rc == 0, err
    ran = [line for line in err.splitlines() if line.startswith("dsm benchmark: ") and f"/{n} " in line]
    assert len(ran) == n - kept == 1                               # the kept cases are not run again
    doc = json.loads((out / "results.json").read_text())
    assert _counts(doc, RESUME_CASES) == _counts(whole, RESUME_CASES) and len(doc["cases"]) == 13 * n
    assert len(doc["flicker"]) > 0                                 # the motion case's, read back from its kept file
    images = lambda d: {p.relative_to(d).as_posix(): p.read_bytes() for p in (d / "case_images").rglob("*.png")}
    assert len(images(out)) == 2 * n and images(out) == {k: v for k, v in images(whole_out).items() if k in images(out)}
    assert not (out / "cases").exists() and (out / "leaderboard.html").is_file()
    assert "dsm benchmark: directional (" in stdout                 # what accuracy costs, in the terminal


@pytest.mark.slow
def test_page_rebuilds_the_leaderboard_from_results_alone(test_run, tmp_path):
    import shutil
    out, _ = test_run
    copy = tmp_path / "copy"
    copy.mkdir()
    shutil.copy(out / "results.json", copy / "results.json")
    assert cli.main(["benchmark", "--page", str(copy)]) == 0
    assert (copy / "leaderboard.html").read_text() == (out / "leaderboard.html").read_text()
    assert (copy / "scale.png").read_bytes() == (out / "scale.png").read_bytes()


@pytest.mark.slow
def test_force_replaces_every_file_of_the_previous_run_and_keeps_the_user_s(tmp_path):
    """--force after a run of another suite: its flicker runs, case files, page and figure are gone
    (none is stale beside the new results); a file the user put there stays."""
    out = tmp_path / "bm"
    for name in ("flicker/dsm-bench-4-x-flicker/frames.csv", "cases/0003.json", "cases/run.json", "scale.png",
                 "leaderboard.html", "results.json", "notes.txt", "case_images/old_m_0/spot_x_flip.png",
                 "contenders/old.html"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("old")
    assert cli.main(["benchmark", "--out", str(out), "--size", "test", "--suite", "dsm-bench-1", "--force"]) == 0
    assert not (out / "flicker").exists() and not (out / "cases").exists()
    assert not (out / "case_images" / "old_m_0").exists() and not (out / "contenders" / "old.html").exists()
    assert (out / "notes.txt").read_text() == "old"
    doc = json.loads((out / "results.json").read_text())
    assert doc["suite"] == "dsm-bench-1" and doc["results_version"] == 5
    assert (out / "leaderboard.html").read_text() != "old" and (out / "scale.png").read_bytes() != b"old"


def _stored(path):
    """An indexed PNG's indices and palette, decoded by Pillow (not the kit's reader)."""
    from PIL import Image
    with Image.open(path) as im:
        assert im.mode == "P", path
        return np.asarray(im), np.asarray(im.getpalette(), np.uint8).reshape(-1, 3)


def _stored_images(out, doc, which):
    """Each record's stored image ((record, indices (32, 32), palette) but the oracles'), cut by hand from
    its case's sheet (Pillow decodes it): a case's records top to bottom in results.json's order."""
    from dsm.benchmark import case_images
    recs = [r for r in doc["cases"] if r["contender"] != "oracle"]
    by_case = {}
    for r in recs:
        by_case.setdefault((r["scene"], r["unit"], r["offset"]), []).append(r)
    out_list = []
    for key, rs in by_case.items():
        sheet, palette = _stored(out / case_images.sheets(rs[0])[which])
        assert sheet.shape == (32 * len(rs), 32), key           # one square image per record, nothing else
        out_list += [(r, sheet[32 * k:32 * (k + 1)], palette) for k, r in enumerate(rs)]
    return out_list


@pytest.mark.slow
def test_a_case_s_stored_class_image_holds_the_counts_of_its_row(test_run):
    """Every record's class image decodes (Pillow) to classes whose counts, recomputed with numpy, are
    the record's receivers, acne and peter-panning; its palette is the error image's colours; the kit's
    reader (case_images.read_class) cuts the same image."""
    from dsm.benchmark import case_images
    from dsm.truth import metrics as m
    out, doc = test_run
    stored = _stored_images(out, doc, 0)
    assert len(stored) == 96 and len(list((out / "case_images").iterdir())) == 2 * 8     # two sheets a case
    for r, classes, palette in stored:
        assert np.array_equal(palette[:len(m.CLASS_COLORS)], m.CLASS_COLORS)
        counts = (int((classes != m.OUTSIDE).sum()), int(np.isin(classes, (m.ACNE, m.ACNE_RESOLUTION)).sum()),
                  int(np.isin(classes, (m.PETERPAN, m.PETERPAN_RESOLUTION, m.LEAK)).sum()))
        assert counts == (r["n_receivers"], r["n_acne"], r["n_peterpan"]), r
    assert any(r["n_acne"] for r, _, _ in stored) and any(r["n_peterpan"] for r, _, _ in stored)   # not all 0
    last = max(i for i, r in enumerate(doc["cases"]) if r["contender"] != "oracle")
    assert np.array_equal(case_images.read_class(out, doc["cases"], last), stored[-1][1])


@pytest.mark.slow
def test_a_case_s_stored_flip_map_s_mean_is_its_row_s_flip_within_the_png_s_quantisation(test_run):
    """A stored FLIP pixel is round(255 FLIP): its mean is within 1/510 of the row's FLIP (FLIP's own
    mean, summed in float32, adds under 1e-5); the palette is matplotlib's magma at i / 255."""
    from matplotlib import colormaps
    from dsm.benchmark import case_images
    out, doc = test_run
    magma = np.round(colormaps["magma"](np.arange(256) / 255.0)[:, :3] * 255).astype(np.uint8)
    off = []
    for r, idx, palette in _stored_images(out, doc, 1):
        assert np.array_equal(palette, magma)
        off.append(abs(idx.astype(np.float64).mean() / 255.0 - r["flip"]))
    assert len(off) == 96 and case_images.FLIP_BOUND == 1 / 510 and max(off) <= 1 / 510 + 1e-5
    assert max(r["flip"] for r in doc["cases"] if "flip" in r) > 10 / 510     # a map with errors, not all black


def _links(path):
    """(attribute, value) of every href and src of an HTML file."""
    from html.parser import HTMLParser
    found = []

    class Links(HTMLParser):
        def handle_starttag(self, tag, attrs):
            found.extend((k, v) for k, v in attrs if k in ("href", "src"))
    Links().feed(path.read_text())
    return found


@pytest.mark.slow
def test_every_link_of_the_leaderboard_and_its_contender_pages_resolves(test_run):
    """Each href and src of leaderboard.html and contenders/*.html names a file that exists, and its
    #fragment an id in it; every contender but the oracle has a page with a card per record of it, and
    the ranking links each contender's name to its page."""
    import re
    from urllib.parse import unquote
    from dsm.benchmark import contenders
    out, doc = test_run
    pages = sorted((out / "contenders").glob("*.html"))
    names = {r["contender"] for r in doc["cases"]} - {"oracle"}
    assert {p.relative_to(out).as_posix() for p in pages} == {contenders.page_path(c) for c in names}
    checked = 0
    for page in [out / "leaderboard.html"] + pages:
        for _, value in _links(page):
            assert not re.match(r"[a-z]+:", value), value                 # from the file system alone
            target, _, frag = unquote(value).partition("#")
            path = (page.parent / target).resolve() if target else page
            assert path.is_file(), (page.name, value)
            if frag:
                assert re.search(rf"\bid={re.escape(frag)}[ >]", path.read_text()), (page.name, value)
            checked += 1
    assert checked > 2 * 96
    ranking_links = re.findall(r'<td><a href="(contenders/[^"]+)">([^<]+)</a>', (out / "leaderboard.html").read_text())
    assert {name for _, name in ranking_links} == names
    for c in names:
        text = (out / contenders.page_path(c)).read_text()
        assert text.count("<figure class=case ") == sum(r["contender"] == c for r in doc["cases"])


def test_a_contenders_page_name_is_its_own_whatever_its_characters():
    """page_path is one file per name: a safe name as it is; one with spaces, a colon, markup, '..', an accent,
    nothing, or 300 characters gets its slug (cut) and a hash, so names of one slug ('msm box:5', 'msm box_5')
    keep apart and none exceeds a file name's 255 bytes (both raised before)."""
    import hashlib
    from dsm.benchmark import contenders
    assert contenders.page_path("bevy") == "contenders/bevy.html"
    odd = ["msm box:5", "msm box_5", "msm_box_5", '<b>a"</b>/../x', "thrée & co", "", ".", "..", "x" * 300, "x" * 301]
    paths = [contenders.page_path(n) for n in odd]
    assert len(set(paths)) == len(odd)
    for n, p in zip(odd, paths):
        name = p.removeprefix("contenders/")
        assert "/" not in name and not name.startswith(".") and len(name.encode()) <= 255
        if n != "msm_box_5":
            assert name.endswith("~" + hashlib.sha256(n.encode()).hexdigest()[:12] + ".html")


def test_contender_pages_of_a_results_folder_without_images_say_so_once(tmp_path):
    """--page on a folder from before case_images/ (results.json alone): each page says once that no images
    were kept, no card carries a 'not kept' note, and a stale page of an earlier naming is removed."""
    from dsm.benchmark import contenders
    cases = [{"scene": s, "unit": "m", "offset": "0", "light": "spot", "contender": c, "n_receivers": 100,
              "n_gt_shadowed": 40, "n_acne": 3, "n_peterpan": 2, "acne_rate": 0.05, "peterpan_rate": 0.05,
              "error_rate": 0.05, "texel_size": 0.01, "build_ms": 1.0, "lookup_ms": 1.0, "params": ""}
             for s in ("a", "b") for c in ("bevy", "msm box:5")]
    doc = {"suite": "dsm-bench-5", "size": "test", "cases": cases}
    (tmp_path / "contenders").mkdir()
    (tmp_path / "contenders" / "msm_box_5.html").write_text("an earlier naming's page")
    written = contenders.write_pages(doc, tmp_path)
    assert sorted(p.name for p in (tmp_path / "contenders").iterdir()) == sorted(p.name for p in written)
    for p in written:
        text = p.read_text()
        assert text.count("<b>No images:</b>") == 1 and "not kept" not in text
        assert text.count("<figure class=case ") == 2


@pytest.mark.slow
def test_frontier_csv_and_memory_classes_from_the_records(test_run):
    """frontier.csv beside results.json: per (scene at its unit, light), on_frontier recomputed in numpy
    from the records at the origin (error from the counts; bytes = map_bytes + page_table_bytes; rays);
    the leaderboard's memory classes hold contenders whose mean bytes lie in [2^k, 2^(k+1)), ranked from 1."""
    import csv

    from dsm.benchmark import costs
    out, doc = test_run
    recs = [r for r in doc["cases"] if r["contender"] != "oracle" and r["offset"] == "0"]
    rows = list(csv.DictReader(open(out / "frontier.csv")))
    assert [(r["scene"], r["instance"]) for r in rows] == [(f"{r['scene']} {r['unit']}", r["contender"]) for r in recs]
    want = []
    for r in recs:
        same = [q for q in recs if (q["scene"], q["unit"], q["light"]) == (r["scene"], r["unit"], r["light"])]
        c = np.array([[(q["n_acne"] + q["n_peterpan"]) / q["n_receivers"], q["map_bytes"] + q["page_table_bytes"],
                       q["map_rays"] + q.get("hybrid_rays", 0)] for q in same], np.float64)   # a hybrid's rays count
        me = c[[q is r for q in same].index(True)]
        want.append("0" if ((c <= me).all(1) & (c < me).any(1)).any() else "1")
    assert [r["on_frontier"] for r in rows] == want and "1" in want
    classes = costs.classes(doc, ranking.ranking(doc))
    assert sum(len(rs) for _, rs in classes) == len({r["contender"] for r in recs})
    for k, rs in classes:
        assert rs[0]["rank"] == 1
        for r in rs:
            mean_bytes = np.mean([q["map_bytes"] + q["page_table_bytes"] for q in recs if q["contender"] == r["contender"]])
            assert 2 ** k <= mean_bytes < 2 ** (k + 1)


@pytest.mark.slow
def test_the_hybrid_contenders_carry_their_rays_beside_their_error(test_run):
    """A hybrid contender's record: ray_fraction = hybrid_rays / n_receivers; at cut-off 8 never more rays than at
    AMD's 0 (its tiles are a subset); the leaderboard's ray fraction is its rays summed over the cases at the origin
    over their receivers (numpy), beside the error; a map alone's cell is a dash; frontier.csv counts the rays."""
    import csv
    import re

    out, doc = test_run
    hyb = [r for r in doc["cases"] if r["contender"].startswith("hybrid ")]
    assert {r["contender"] for r in hyb} == {"hybrid classifier", "hybrid classifier cutoff 8"} and len(hyb) == 16
    for r in hyb:
        assert r["ray_fraction"] == r["hybrid_rays"] / r["n_receivers"] and 0 < r["hybrid_rays"] <= r["n_receivers"]
        assert r["error_rate"] == (r["n_acne"] + r["n_peterpan"]) / r["n_receivers"]
    key = lambda r: (r["scene"], r["unit"], r["offset"], r["light"])
    amd = {key(r): r for r in hyb if r["contender"] == "hybrid classifier"}
    cut = {key(r): r for r in hyb if r["contender"] == "hybrid classifier cutoff 8"}
    assert amd.keys() == cut.keys() and all(cut[k]["hybrid_rays"] <= amd[k]["hybrid_rays"] for k in amd)
    assert any(cut[k]["hybrid_rays"] < amd[k]["hybrid_rays"] for k in amd)     # the cut-off drops some tile here
    page = (out / "leaderboard.html").read_text()
    table = page[page.index('id=ranking') if 'id=ranking' in page else page.index('id="ranking"'):]
    table = table[:table.index("</table>")]
    head = [re.sub("<[^>]+>", "", h) for h in re.findall(r"<th[^>]*>(.*?)</th>", table, re.S)]
    at = head.index("ray fraction")
    assert head[at - 1] == "error rate"
    cells = {}
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", table, re.S)[1:]:
        tds = [re.sub("<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)]
        cells[tds[head.index("contender")]] = tds[at]
    for name in ("hybrid classifier", "hybrid classifier cutoff 8"):
        here = [r for r in hyb if r["contender"] == name and r["offset"] == "0"]
        want = np.sum([r["hybrid_rays"] for r in here], dtype=np.float64) / np.sum([r["n_receivers"] for r in here])
        assert cells[name] == f"{want:.4g}", (name, cells[name])
        assert {r["contender"]: r for r in ranking.ranking(doc)}[name]["ray_fraction"] == pytest.approx(want, rel=1e-15)
    assert cells["bevy"] == "\u2014" and cells["vsm box:5"] == "\u2014"
    rows = [r for r in csv.DictReader(open(out / "frontier.csv")) if r["instance"] == "hybrid classifier"]
    want_rays = sorted(r["map_rays"] + r["hybrid_rays"] for r in hyb if r["contender"] == "hybrid classifier"
                       and r["offset"] == "0")
    assert sorted(int(r["rays"]) for r in rows) == want_rays


def test_a_hybrid_record_whose_rays_disagree_is_refused_in_one_line():
    """results version 5: a hybrid record's rays are a count of at most its receivers and ray_fraction their share."""
    from dsm.benchmark import document
    rec = {"scene": "s", "unit": "m", "light": "directional", "contender": "hybrid classifier", "n_receivers": 10,
           "n_acne": 0, "n_peterpan": 0, "map_bytes": 4, "page_table_bytes": 0, "map_rays": 1, "taps": 1.0,
           "hybrid_rays": 4, "ray_fraction": 0.4}
    doc = {"results_version": 5, "suite": "dsm-bench-6", "cases": [rec],
           "versions": {"dsm": "0", "mitsuba": "3", "drjit": "1"}}
    assert document.check(doc) is doc
    for bad, word in (({"ray_fraction": 0.5}, "ray_fraction"), ({"hybrid_rays": 2.0}, "hybrid_rays"),
                      ({"hybrid_rays": 11, "ray_fraction": 1.1}, "hybrid_rays")):
        with pytest.raises(document.NotResults, match=rf"^<document>: cases\[0\]\.{word} is [^\n]*$"):
            document.check({**doc, "cases": [{**rec, **bad}]})
