"""dsm benchmark (dsm-bench-1): the suite's hash pin, its scale normalization, the compare rule,
the leaderboard's ranking and tie rule, the preset bias conversion, and one tiny end-to-end run."""
import json

import numpy as np
import pytest

from dsm import cli
from dsm.benchmark import bias_units, compare, ranking, suite
from dsm.benchmark.command import SIZE_ENV
from dsm.types import Length

# the suite's identity: changing suite_1.toml changes this, which makes it dsm-bench-2
SUITE_1_SHA256 = "15b8554a6f096049e4da44ba45084ae524f5d93f04380a71907185a990a2ba5c"


def test_suite_hash_is_pinned():
    assert suite.suite_sha256() == SUITE_1_SHA256
    s = suite.load_suite()
    assert s["suite"]["name"] == "dsm-bench-1"


def test_default_size_covers_every_preset_scene_unit_and_light():
    from dsm.schemes.presets import names
    s = suite.load_suite()
    cs = suite.cases(s, "default")
    assert len(cs) == len(s["scene"]) * 3                     # every scene at cm, m and km
    schemes = cs[0].config["scheme"]
    assert sorted(t["preset"] for t in schemes if "preset" in t) == names()
    assert [t["type"] for t in cs[0].config["light"]] == ["scene", "spot", "point"]
    assert cs[0].config["map"]["cascades"] == 4


def _by(cs, scene, unit):
    return next(c for c in cs if c.scene == scene and c.unit == unit)


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


def _rec(contender, unit, n_acne, n_peterpan=0, n_receivers=1000, scene="s", light="directional"):
    return {"scene": scene, "unit": unit, "light": light, "contender": contender, "n_receivers": n_receivers,
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
    assert [c["case"][3] for c in diff["changed"]] == ["q", "t"]     # moves 3 > 2 and 6 > 5
    assert diff["changed"][0]["moves"] == [["n_acne", 10, 13]]
    assert diff["n_tied"] == 2                                         # p (2 <= 2) and r (4 <= 5)
    assert diff["added"] == [["s", "m", "directional", "new"]]
    assert diff["removed"] == [["s", "m", "directional", "gone"]]
    assert diff["same_suite"]


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


def test_benchmark_end_to_end_at_test_size(tmp_path, monkeypatch):
    monkeypatch.setenv(SIZE_ENV, "test")
    assert cli.main(["benchmark", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["suite"] == "dsm-bench-1" and doc["suite_sha256"] == SUITE_1_SHA256 and doc["size"] == "test"
    assert doc["machine"]["cores"] >= 1 and doc["versions"]["dsm_git_commit"]
    # 2 scenes x 2 units x 1 light x (3 contenders + the oracle)
    assert len(doc["cases"]) == 16
    recs = {(r["scene"], r["unit"], r["contender"]): r for r in doc["cases"]}
    for r in doc["cases"]:
        if r["contender"] != "oracle":
            assert r["error_rate"] == pytest.approx((r["n_acne"] + r["n_peterpan"]) / r["n_receivers"])
    # the texel width follows the unit: 100 times wider in cm (the map is fitted to the scene)
    assert recs[("bunny", "cm", "bevy")]["texel_size"] == pytest.approx(
        100 * recs[("bunny", "m", "bevy")]["texel_size"], rel=1e-3)
    page = (tmp_path / "leaderboard.html").read_text()
    assert "Ranking" in page and "Oracle floor" in page and "three" in page and "http" not in page
    assert "function sortBy" in page and "class=sortable" in page           # report.html's header sort


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
