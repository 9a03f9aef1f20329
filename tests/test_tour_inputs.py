"""Issue 76's second hostile tour: the inputs on the newest surfaces (the frontier, results version 4,
hybrid rays, dsm plan's rays, dsm tune's Optuna journal) that were mishandled, each answered now. A
refusal: exit 2, one line naming the file, key or flag and what is valid, and no file outside the
command's own written or lost. Expected values come from outside the code under test (the counts
written into the files here, numpy float64, Optuna's own journal reader)."""
import csv
import json
import math
import shutil

import numpy as np
import pytest

from conftest import base_config, cli_run, one_line, write_toml


def _files(folder) -> dict:
    """Every file under ``folder`` with its bytes (the lock file aside)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".dsm-lock"}


def _toml(path, cfg: dict):
    return write_toml(path, cfg)


# ---------------------------------------------------------------- results.json (--page, --compare)

REC = {"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p", "n_receivers": 100,
       "n_gt_shadowed": 10, "n_acne": 3, "n_peterpan": 1, "acne_rate": 3 / 90, "peterpan_rate": 1 / 10,
       "error_rate": 4 / 100, "flip": 0.01, "map_bytes": 4096, "page_table_bytes": 0, "map_rays": 1024, "taps": 1.0}
DOC = {"results_version": 4, "suite": "dsm-bench-5", "suite_sha256": "x", "size": "test", "dsm_version": "0",
       "versions": {"dsm": "0", "mitsuba": "3", "drjit": "1"}, "variant": "llvm_ad_rgb", "machine": {},
       "cases": [REC]}

DAMAGED = {  # what the tour wrote into results.json -> (the edit, words of the one line)
    "taps = -1 (exit 0 before)": ({"case": {"taps": -1.0}}, ["cases[0].taps is -1.0", "a number >= 0"]),
    "size 'huge' (exit 0)": ({"doc": {"size": "huge"}}, ["size 'huge' is not a size", "test, default, full"]),
    "size 5 (exit 0)": ({"doc": {"size": 5}}, ["size 5 is not a size", "test, default, full"]),
    "an unknown suite (exit 0)": ({"doc": {"suite": "dsm-bench-9"}}, ["suite 'dsm-bench-9'", "dsm-bench-5"]),
    "light 'area' (a KeyError)": ({"case": {"light": "area"}},
                                  ["cases[0].light is 'area'", "directional, spot, point"]),
    "n_acne above the lit receivers (exit 0)": ({"case": {"n_acne": 99999}},
                                                ["n_acne 99999", "do not fit", "n_receivers 100"]),
    "n_receivers 0, rates kept (exit 0)": ({"case": {"n_receivers": 0}}, ["n_receivers 0", "do not fit"]),
    "error_rate NaN over 100 receivers (exit 0)": ({"case": {"error_rate": float("nan")}},
                                                   ["error_rate nan is not 4 / 100"]),
    "an acne rate of other counts (exit 0)": ({"case": {"acne_rate": 0.5}}, ["acne_rate 0.5 is not 3 / 90"]),
}


def _doc(edit: dict) -> dict:
    return {**DOC, **edit.get("doc", {}), "cases": [{**REC, **edit.get("case", {})}]}


def test_the_good_document_is_read(tmp_path, capsys):
    from dsm.benchmark import document
    assert document.check(json.loads(json.dumps(DOC)))["cases"][0]["error_rate"] == 0.04
    no_cases = {**REC, "error_rate": float("nan"), "n_receivers": 0, "n_gt_shadowed": 0, "n_acne": 0,
                "n_peterpan": 0, "acne_rate": float("nan"), "peterpan_rate": float("nan"), "taps": float("nan")}
    assert document.counts_problem(no_cases) is None          # no receiver: every rate undefined (NaN), taps too
    document.check({**DOC, "cases": [no_cases]})


@pytest.mark.parametrize("name", list(DAMAGED))
def test_page_and_compare_refuse_what_the_tour_wrote_into_results_json(name, tmp_path, capsys):
    edit, words = DAMAGED[name]
    folder = tmp_path / "b"
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps(_doc(edit)))
    (tmp_path / "good.json").write_text(json.dumps(DOC))
    before = _files(tmp_path)
    rc, err = cli_run(capsys, "benchmark", "--page", folder)
    assert rc == 2
    one_line(err, "--page", str(folder / "results.json"), *words)
    rc, err = cli_run(capsys, "benchmark", "--compare", tmp_path / "good.json", folder / "results.json",
                      "--out", tmp_path / "cmp")
    assert rc == 2
    one_line(err, "--compare", *words)
    assert _files(tmp_path) == before and not (tmp_path / "cmp").exists()


def test_a_kept_case_meets_the_same_counts_rule(tmp_path):
    """caselog.consistent and results.json's reader read one rule: a kept case edited as the tour edited
    results.json runs again."""
    from dsm.benchmark import caselog
    assert caselog.consistent(dict(REC))
    for edit, _ in DAMAGED.values():
        case = edit.get("case", {})
        if set(case) & {"n_acne", "n_receivers", "error_rate", "acne_rate"}:
            assert not caselog.consistent({**REC, **case}), case
    assert not caselog.consistent({k: v for k, v in REC.items() if k != "peterpan_rate"})   # a kept case is whole


@pytest.mark.parametrize("argv", [["--size", "test", "--size", "default"], ["--size", "default", "--size", "test"],
                                  ["--size", "test", "--size", "full"]])
def test_two_sizes_are_refused_as_size_with_full_is(argv, tmp_path, capsys, monkeypatch):
    from dsm.benchmark import results
    monkeypatch.setattr(results, "run_suite", lambda *a, **k: pytest.fail("the suite ran at the last --size"))
    out = tmp_path / "bm"
    rc, err = cli_run(capsys, "benchmark", *argv, "--out", out)
    assert rc == 2
    one_line(err, f"--size {argv[1]} and --size {argv[3]} disagree", "give one --size")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_the_same_size_twice_is_one_size():
    import argparse

    from dsm.benchmark import command
    p = argparse.ArgumentParser()
    command.add_parser(p.add_subparsers(dest="cmd"))
    args = p.parse_args(["benchmark", "--size", "test", "--size", "test"])
    assert command.size_problem(command.size_spellings(args, {})) is None and args.size == "test"


# ---------------------------------------------------------------- a run's metrics.csv and frontier.csv

@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A run of two schemes at two map sizes on one scene: six cases, a frontier of several points."""
    import dsm
    out = tmp_path_factory.mktemp("tour") / "run"
    dsm.run(base_config(camera={"resolution": [32, 32]}, scene=[{"builtin": "plane_box"}],
                        map={"resolution": [32, 64]},
                        scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"}, {"name": "none"}],
                        report={"images": "none"}), out=out)
    return out


def _edit_cell(col, value):
    def f(path):
        rows = list(csv.reader(open(path, newline="")))
        rows[1][rows[0].index(col)] = value
        csv.writer(open(path, "w", newline="")).writerows(rows)
    return f


def _drop_column(col):
    def f(path):
        rows = list(csv.reader(open(path, newline="")))
        i = rows[0].index(col)
        csv.writer(open(path, "w", newline="")).writerows([r[:i] + r[i + 1:] for r in rows])
    return f


EDITED = {  # metrics.csv as the tour edited it -> words of the one line
    "map_bytes = -5 (exit 0, on the frontier)": (_edit_cell("map_bytes", "-5"),
                                                 ["case 0001: map_bytes -5 is not a count"]),
    "map_bytes empty (a traceback)": (_edit_cell("map_bytes", ""), ["case 0001: map_bytes nan is not a count"]),
    "taps = -1 (exit 0)": (_edit_cell("taps", "-1"), ["case 0001: taps -1.0", "a number >= 0"]),
    "page_table_bytes = -1 (exit 0)": (_edit_cell("page_table_bytes", "-1"), ["page_table_bytes -1 is not a count"]),
    "no map_bytes column (exit 0, no frontier)": (_drop_column("map_bytes"), ["no map_bytes column", "map_rays"]),
    "no map_rays column (a KeyError)": (_drop_column("map_rays"), ["no map_rays column", "map_bytes"]),
}


@pytest.mark.parametrize("name", list(EDITED))
def test_report_refuses_an_edited_cost_column(name, tiny_run, tmp_path, capsys):
    edit, words = EDITED[name]
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    edit(run / "metrics.csv")
    before = _files(run)
    rc, err = cli_run(capsys, "report", run)
    assert rc == 2
    one_line(err, str(run / "metrics.csv"), "an edited file", *words)
    assert _files(run) == before


def _frontier_float64(metrics_csv) -> list:
    """on_frontier of each row as the design defines it, computed here in float64 from the counts: no
    other point has error, bytes and rays each at most its own and one lower; undefined error: ''."""
    rows = list(csv.DictReader(open(metrics_csv)))
    pts = np.array([[(float(r["n_acne"]) + float(r["n_peterpan"])) / float(r["n_receivers"])
                     if float(r["n_receivers"]) else math.nan,
                     float(r["map_bytes"]) + float(r["page_table_bytes"]), float(r["map_rays"])] for r in rows])
    out = []
    for p in pts:
        others = pts[~np.isnan(pts[:, 0])]
        beaten = np.any(np.all(others <= p, axis=1) & np.any(others < p, axis=1))
        out.append("" if math.isnan(p[0]) else ("0" if beaten else "1"))
    return out


def test_a_rebuilt_frontier_is_the_one_its_counts_give_and_none_without_rows(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / "frontier.csv").write_text("scene,on_frontier\nforged,1\n")
    rc, _ = cli_run(capsys, "report", run)
    assert rc == 0
    got = [r["on_frontier"] for r in csv.DictReader(open(run / "frontier.csv"))]
    assert got == _frontier_float64(run / "metrics.csv") and "1" in got and "0" in got
    header = (run / "metrics.csv").read_text().splitlines()[0]
    (run / "metrics.csv").write_text(header + "\n")          # every row gone: no frontier of rows not there
    rc, err = cli_run(capsys, "report", run)
    assert rc == 0 and any("have no row" in line for line in err)
    assert not (run / "frontier.csv").exists()
    assert {"run.json", "metrics.csv", "report.html", "table.md"} <= set(_files(run))


# ---------------------------------------------------------------- [hybrid]: instances, the plan's rays

def test_an_instance_given_by_two_hybrid_tables_is_refused(tmp_path, capsys):
    tables = [{"rule": "band", "k": [0.1, 1.0]}, {"rule": "band", "k": [1.0, 3.0]}]
    cfg = _toml(tmp_path / "h.toml", base_config(camera={"resolution": [32, 32]}, map={"resolution": 32},
                                                 hybrid=tables))
    before = _files(tmp_path)
    rc, err = cli_run(capsys, "run", cfg, "--out", tmp_path / "out")
    assert rc == 2
    one_line(err, str(cfg), "hybrid[1]", "band k=1.0 from spawn is already hybrid[0]'s", "give each instance once")
    assert _files(tmp_path) == before and not (tmp_path / "out").exists()


def test_the_plan_bounds_the_hybrid_rays_the_run_casts(tmp_path):
    """rule all from two origins: a ray per receiver per origin. The plan's bound is the camera's pixels
    per hybrid case; run.json's count is the sum of the rows' hybrid_rays, each its case's receivers."""
    import dsm
    from dsm.config import plan, read
    raw = base_config(camera={"resolution": [32, 24]}, scene=[{"builtin": "plane_box"}], map={"resolution": 32},
                      scheme=[{"name": "constant", "bias": "1 texel"}], report={"images": "none"},
                      hybrid={"rule": "all", "origin": ["spawn", "epsilon"]})
    p = plan.make(read.parse(raw, "<t>"))
    assert p.rays_bound["hybrid"] == 2 * 32 * 24
    assert "hybrid" not in plan.make(read.parse({k: v for k, v in raw.items() if k != "hybrid"}, "<t>")).rays_bound
    res = dsm.run(raw, out=tmp_path / "out")
    rows = list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))
    assert [int(r["hybrid_rays"]) for r in rows] == [int(r["n_receivers"]) for r in rows] and len(rows) == 2
    assert res.run["rays"]["hybrid"] == sum(int(r["n_receivers"]) for r in rows) <= p.rays_bound["hybrid"]


# ---------------------------------------------------------------- dsm tune: the Optuna journal

def _journal_with_trials(folder, n: int):
    """A study of ``n`` completed trials in folder/optuna.journal, written by Optuna itself."""
    optuna = pytest.importorskip("optuna")
    from optuna.storages.journal import JournalFileBackend
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    store = optuna.storages.JournalStorage(JournalFileBackend(str(folder / "optuna.journal")))
    study = optuna.create_study(study_name="s", storage=store, sampler=optuna.samplers.RandomSampler(seed=1))
    study.optimize(lambda t: t.suggest_float("x", 0.0, 1.0) ** 2, n_trials=n)
    return optuna, [t.params["x"] for t in study.trials]


def _complete(optuna, folder) -> list:
    from optuna.storages.journal import JournalFileBackend
    store = optuna.storages.JournalStorage(JournalFileBackend(str(folder / "optuna.journal")))
    study = optuna.load_study(study_name="s", storage=store)
    return [t.params["x"] for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]


def test_an_append_a_kill_cut_short_is_cut_off_before_the_resume_appends(tmp_path):
    """kill -9 while Optuna appends leaves a last line without its newline; the resume's next record
    joined it into a line Optuna could not read (a JSONDecodeError, the study lost)."""
    from dsm.tune import blackbox
    optuna, xs = _journal_with_trials(tmp_path, 3)
    raw = (tmp_path / "optuna.journal").read_bytes()
    (tmp_path / "optuna.journal").write_bytes(raw[:-37])           # the last record cut short
    assert blackbox.journal_problem(tmp_path) is None
    kept = (tmp_path / "optuna.journal").read_bytes()
    assert kept.endswith(b"\n") and raw.startswith(kept) and len(kept) == raw.rfind(b"\n", 0, len(raw) - 37) + 1
    from optuna.storages.journal import JournalFileBackend
    store = optuna.storages.JournalStorage(JournalFileBackend(str(tmp_path / "optuna.journal")))
    study = optuna.load_study(study_name="s", storage=store)
    study.optimize(lambda t: t.suggest_float("x", 0.0, 1.0) ** 2, n_trials=1)       # the resume appends
    got = _complete(optuna, tmp_path)
    assert got[:2] == xs[:2] and len(got) == 3                     # the two whole trials kept, one more run


@pytest.mark.parametrize("damage", [b"\x00\x01garbage\n{not json\n", b"[1, 2]\n"])
def test_resume_refuses_a_damaged_journal_in_one_line(damage, tmp_path, capsys):
    from dsm.tune import resume as tune_resume
    cfg = _toml(tmp_path / "t.toml", base_config(
        camera={"resolution": [32, 32]}, scene=[{"builtin": "plane_box"}], map={"resolution": 32},
        scheme=[{"name": "constant", "bias": "1 texel"}], tune={"steps": 4, "search": "optuna"}))
    out = tmp_path / "tune"
    out.mkdir()
    tune_resume.write_state(out, "test", [])
    (out / "optuna.journal").write_bytes(damage)
    (out / "notes.txt").write_text("mine")
    before = _files(tmp_path)
    pytest.importorskip("optuna")
    rc, err = cli_run(capsys, "tune", cfg, "--out", out, "--resume")
    assert rc == 2
    one_line(err, f"{out / 'optuna.journal'} line 1", "not a record of Optuna's journal", "--force")
    assert _files(tmp_path) == before
