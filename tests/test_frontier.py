"""What accuracy costs: a case's costs in counts (dsm.case.cost), the frontier (dsm.report.frontier)
and its answer in words, checked against analytic byte counts and a numpy recomputation."""
import csv

import numpy as np
import pytest

from conftest import base_config

MIB = 2 ** 20


def _by(rows, **want):
    out = [r for r in rows if all(r[k] == v for k, v in want.items())]
    assert out, want
    return out


def test_bytes_rays_and_taps_of_depth_maps(run_dict):
    """512^2 float32, one layer: 1 MiB; a second layer (midpoint's z2) twice; unorm16 half; the slope
    layer 4 more bytes a texel; one ray a texel without culling; taps 1, 4 and K^2."""
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [24, 24]},
                      map={"resolution": 512, "format": ["float32", "unorm16"],
                           "filter": ["nearest", "pcf_bilinear", "pcf_wide:3"]},
                      scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "midpoint"},
                              {"name": "slope_scaled"}])
    rows = run_dict(cfg).rows
    texels = 512 * 512
    for r in _by(rows, scheme="constant", format="float32"):
        assert r["map_bytes"] == MIB and r["page_table_bytes"] == 0 and r["map_rays"] == texels
    for r in _by(rows, scheme="constant", format="unorm16"):
        assert r["map_bytes"] == MIB // 2
    for r in _by(rows, scheme="midpoint", format="float32"):
        assert r["map_bytes"] == 2 * MIB and r["map_rays"] > texels     # z2: the layered search's rays too
    for r in _by(rows, scheme="midpoint", format="unorm16"):
        assert r["map_bytes"] == MIB
    for r in _by(rows, scheme="slope_scaled", format="unorm16"):
        assert r["map_bytes"] == texels * (2 + 4)
    taps = {"nearest": 1, "pcf_bilinear": 4, "pcf_wide:3": 9}
    for r in rows:
        assert r["taps"] == taps[r["filter"]]


@pytest.mark.slow
def test_bytes_of_cascades_virtual_and_moment_maps(run_dict):
    """3 cascades: 3 R^2 texels; a virtual map: its built pages x page texels x 4, its page table one
    32-bit entry per virtual page of every level; VSM's 2 and MSM's 4 moments a texel, x 4/3 with mip-maps."""
    casc = run_dict(base_config(scene=[{"builtin": "long_ground"}], camera={"resolution": [32, 32]},
                                map={"resolution": 128, "cascades": 3},
                                scheme=[{"name": "constant", "bias": "1 texel"}]), "casc").rows
    assert [r["map_bytes"] for r in casc] == [3 * 128 * 128 * 4]
    page, res = 64, 4096
    vsm = run_dict(base_config(scene=[{"builtin": "long_ground"}], camera={"resolution": [32, 32]},
                               map={"virtual": {"preset": ["ue5"], "resolution": res, "page_size": page,
                                                "levels": 6}},
                               scheme=[{"name": "constant", "bias": "1 texel"}]), "vsm").rows
    for r in vsm:
        assert r["map_bytes"] == r["vsm_pages_built"] * page ** 2 * 4 > 0
        assert r["page_table_bytes"] == 6 * (res // page) ** 2 * 4
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [24, 24]},
                      map={"resolution": 64, "kind": ["vsm", "msm"], "mipmaps": [False, True]})
    del cfg["scheme"]
    pre = run_dict(cfg, "pre").rows
    moments = {"vsm": 2, "msm": 4}
    for r in pre:
        mip = r["filter"].endswith("/mip")
        assert r["map_bytes"] == round(64 * 64 * moments[r["scheme"]] * 4 * (4 / 3 if mip else 1))
        assert r["taps"] == (2 if mip else 1) and r["map_rays"] == 64 * 64


def test_pcss_taps_count_the_blocker_search_and_the_filter_where_it_runs(run_dict):
    """PCSS: 36 search taps at every receiver, 49 filter taps only where the search found a blocker;
    a shadow in view: some do, not all."""
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                      light=[{"type": "area", "shape": "rectangle", "position": [0.5, -0.5, 3.0],
                              "direction": [0.0, 0.0, -1.0], "size": 0.5, "max_samples": 64}],
                      map={"resolution": 64, "filter": ["pcss"]}, scheme=[{"name": "constant"}])
    (r,) = run_dict(cfg).rows
    assert 36 < r["taps"] < 36 + 49
    assert r["taps"] == pytest.approx(36 + 49 * round((r["taps"] - 36) / 49 * r["n_receivers"]) / r["n_receivers"])


def _frontier_numpy(rows):
    """on_frontier per row, recomputed: within each (scene, light), no other row has error, bytes and
    rays each at most its own with one lower; '' where the error is undefined."""
    out = [""] * len(rows)
    groups = {}
    for i, r in enumerate(rows):
        if int(r["n_receivers"]):
            groups.setdefault((r["scene"], r["light"]), []).append(i)
    for idx in groups.values():
        c = np.array([[(int(rows[i]["n_acne"]) + int(rows[i]["n_peterpan"])) / int(rows[i]["n_receivers"]),
                       int(rows[i]["map_bytes"]) + int(rows[i]["page_table_bytes"]), int(rows[i]["map_rays"])]
                      for i in idx], np.float64)
        dominated = ((c[None, :, :] <= c[:, None, :]).all(-1) & (c[None, :, :] < c[:, None, :]).any(-1)).any(1)
        for k, i in enumerate(idx):
            out[i] = "0" if dominated[k] else "1"
    return out


FRONTIER_CONFIG = base_config(
    scene=[{"builtin": "plane_box"}, {"builtin": "l_shape"}, {"builtin": "grazing", "angle": 85}],
    camera={"resolution": [40, 40]},
    light=[{"type": "scene"}, {"type": "spot", "position": [-2.0, 2.5, 2.6], "target": [0, 0, 0], "cutoff": 40}],
    map={"resolution": [64, 128, 256], "format": ["float32", "unorm16"]},
    scheme=[{"name": "none"}, {"name": "constant", "bias": ["1 texel", "2 texel"]}, {"name": "normal_angle"},
            {"name": "receiver_plane"}, {"name": "midpoint"}])


@pytest.mark.slow
def test_frontier_csv_is_non_dominance_over_error_bytes_and_rays(tmp_path):
    import dsm
    res = dsm.run(FRONTIER_CONFIG, out=tmp_path / "run")
    metrics = list(csv.DictReader(open(tmp_path / "run" / "metrics.csv")))
    front = list(csv.DictReader(open(tmp_path / "run" / "frontier.csv")))
    assert len(front) == len(metrics) == len(res.rows)
    assert [r["on_frontier"] for r in front] == _frontier_numpy(metrics)
    assert 0 < sum(r["on_frontier"] == "1" for r in front) < len(front)
    table = (tmp_path / "run" / "table.md").read_text()
    assert table.index("## What accuracy costs") < table.index("## Summary")


@pytest.mark.slow
def test_two_identical_runs_give_the_same_frontier_and_words(tmp_path):
    import dsm
    from dsm.report import frontier
    cfg = {**FRONTIER_CONFIG, "scene": FRONTIER_CONFIG["scene"][:2], "map": {"resolution": [64, 128]}}
    texts, words = [], []
    for name in ("a", "b"):
        res = dsm.run(cfg, out=tmp_path / name)
        rows = list(csv.DictReader(open(tmp_path / name / "frontier.csv")))
        texts.append([{k: v for k, v in r.items() if k not in frontier.TIME_COLUMNS} for r in rows])
        words.append(frontier.answer_lines(frontier.answers(frontier.points_from_rows(res.rows))))
    assert texts[0] == texts[1] and words[0] == words[1] and words[0]


def _point(scene, inst, error, n_bytes, rays=1000):
    from dsm.report.frontier import Point
    return Point(scene, "0:directional", "directional", inst, inst.split()[0], error, n_bytes, rays, 1.0, 1.0, 0.1)


def test_the_lowest_error_at_30x_the_bytes_is_on_the_frontier_and_the_answer_names_the_cheaper():
    """A made-up light type: 'big' has the lowest error at 30x the bytes of 'small', whose per-situation
    differences from it change sign (the bootstrap cannot tell them apart); 'worse' costs more than
    small and errs more."""
    from dsm.report import frontier
    big = [0.010, 0.011, 0.009, 0.010, 0.0095]
    small = [0.012, 0.009, 0.011, 0.0105, 0.0093]
    pts = []
    for i, (b, s) in enumerate(zip(big, small)):
        pts += [_point(f"s{i}", "big at 2048", b, 30 * MIB), _point(f"s{i}", "small at 512", s, MIB),
                _point(f"s{i}", "worse at 1024", s + 0.01, 4 * MIB)]
    marks = dict(zip([(p.scene, p.instance) for p in pts], frontier.on_frontier(pts)))
    for i, (b, s) in enumerate(zip(big, small)):      # big is on a situation's frontier where it errs less
        assert marks[(f"s{i}", "big at 2048")] == (b < s) and marks[(f"s{i}", "small at 512")]
        assert marks[(f"s{i}", "worse at 1024")] is False
    (a,) = frontier.answers(pts)
    assert a["best"].instance == "big at 2048" and a["chosen"].instance == "small at 512"
    lines = frontier.answer_lines([a])
    assert lines[0].startswith("directional (5 situations): small at 512: error 0.01")
    assert "the lowest, 0.0099, costs 30x the memory: big at 2048 (30 MiB" in lines[1]


def test_an_undefined_error_is_on_no_frontier_and_a_tie_is_on_it_twice():
    from dsm.report import frontier
    pts = [_point("s", "a at 64", float("nan"), 10), _point("s", "b at 64", 0.1, 10), _point("s", "c at 64", 0.1, 10)]
    assert frontier.on_frontier(pts) == [None, True, True]


def test_the_leaderboard_ranks_inside_memory_classes_and_says_the_console_s_words(tmp_path):
    """A made-up version 4 document: 'big' errs least at 30x the bytes of 'small' (a tie the cases cannot
    break); the page's first answer is the console's line, the ranking groups big and small apart (each
    first in its class), and the class headline names both."""
    import html as html_mod

    from dsm.benchmark import costs, page, ranking
    big, small = [0.010, 0.011, 0.009, 0.010, 0.0095], [0.012, 0.009, 0.011, 0.0105, 0.0093]
    cases = []
    for i, (b, s) in enumerate(zip(big, small)):
        for name, err, n_bytes in (("big", b, 30 * MIB), ("small", s, MIB)):
            cases.append({"scene": f"s{i}", "unit": "m", "offset": "0", "light": "directional", "contender": name,
                          "n_receivers": 10000, "n_acne": round(err * 10000), "n_peterpan": 0, "acne_rate": err,
                          "peterpan_rate": 0.0, "error_rate": round(err * 10000) / 10000, "texel_size": 0.01,
                          "build_ms": 1.0, "lookup_ms": 1.0, "map_bytes": n_bytes, "page_table_bytes": 0,
                          "map_rays": 1000, "taps": 1.0})
    doc = {"results_version": 4, "suite": "dsm-bench-5", "suite_sha256": "0" * 64, "size": "test", "dsm_version": "0",
           "variant": "x", "versions": {"dsm_git_commit": "c", "dsm": "0", "mitsuba": "3", "drjit": "1"},
           "machine": {"cpu": "cpu", "cores": 1}, "cases": cases}
    text = html_mod.unescape(page.write_page(doc, tmp_path).read_text())
    head = costs.answer_lines(doc)[0]
    assert head.startswith("directional (5 situations): small: error 0.01")
    assert head.split(" (the cheapest")[0] in text
    classes = costs.classes(doc, ranking.ranking(doc))
    assert [(k, [r["contender"] for r in rs], [r["rank"] for r in rs]) for k, rs in classes] == [
        (20, ["small"], [1]), (24, ["big"], [1])]
    assert "1 MiB to 2 MiB: small" in text and "16 MiB to 32 MiB: big" in text


@pytest.mark.slow
def test_a_hybrid_case_is_the_map_alone_and_the_map_with_its_rays(run_dict):
    """[hybrid]: each map case is one point alone (its own counts) and one per rule, the error left after the
    rays and the rays traced added to the map's ('all' traces every receiver: error 0, map rays + receivers);
    the oracle rule reads V*: the floor, on no frontier and in no answer."""
    from dsm.report import frontier
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [40, 40]}, map={"resolution": 64},
                      scheme=[{"name": "constant", "bias": "1 texel"}],
                      hybrid=[{"rule": "band", "k": 2.0}, {"rule": "oracle"}, {"rule": "all"}])
    rows = run_dict(cfg).rows
    pts = frontier.points_from_rows(rows)
    assert len(pts) == 1 + 2 and not any("oracle" in p.instance for p in pts)
    alone, band, every = pts
    r = rows[0]
    assert alone.error == (r["n_acne"] + r["n_peterpan"]) / r["n_receivers"] and alone.rays == r["map_rays"]
    assert every.error == 0 and every.rays == r["map_rays"] + r["n_receivers"] and every.bytes == alone.bytes
    assert band.instance.endswith("+ rays: band k=2.0") and alone.rays < band.rays < every.rays
