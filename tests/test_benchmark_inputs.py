"""dsm benchmark's answers to bad input: every --compare file that is not a results document, and
flags that do not apply, get one line naming the file or flag, exit 2, and nothing written."""
import json

import pytest

from conftest import cli_lines, cli_run, one_line, folder_files
from dsm import cli
from dsm.benchmark import caselog, compare, document

GOOD = {"suite": "dsm-bench-4", "suite_sha256": "x", "cases": [
    {"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p", "n_receivers": 100,
     "n_acne": 3, "n_peterpan": 1, "flip": 0.01}],
    "flicker": [{"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p",
                 "flicker_rate": 0.01}]}


def _case(**over):
    return {**GOOD, "cases": [{**GOOD["cases"][0], **over}]}


# (what the file holds, a word its one-line answer must say)
BAD = {
    "truncated": (json.dumps(GOOD)[:40].encode(), "not JSON"),
    "empty": (b"", "empty"),
    "binary": (bytes(range(256)), "not UTF-8"),
    "utf16": (json.dumps(GOOD).encode("utf-16"), "not UTF-8"),
    "nan": (b"NaN", "a number"),
    "list": (b"[1, 2]", "a list"),
    "null": (b"null", "null"),
    "empty object": (b"{}", "no suite"),
    "a dsm run's run.json": (json.dumps({"state": "complete", "plan": {}, "scheme_instances": 3}).encode(), "run.json"),
    "a case without scene": (json.dumps(_case(scene=None)).encode(), "scene"),
    "flicker without its keys": (json.dumps({**GOOD, "flicker": [{"scene": "s"}]}).encode(), "flicker[0]"),
    "counts as strings": (json.dumps(_case(n_acne="3")).encode(), "n_acne"),
    "counts as null": (json.dumps(_case(n_peterpan=None)).encode(), "n_peterpan"),
    "negative count": (json.dumps(_case(n_receivers=-1)).encode(), "n_receivers"),
    "cases not a list": (json.dumps({**GOOD, "cases": "x"}).encode(), "cases"),
    "a newer version": (json.dumps({**GOOD, "results_version": 99}).encode(), "results_version"),
}


@pytest.mark.parametrize("name", list(BAD) + ["missing", "a folder"])
def test_compare_answers_every_bad_file_in_one_line(name, tmp_path, capsys):
    good = tmp_path / "good.json"
    good.write_text(json.dumps(GOOD))
    bad = tmp_path / "bad.json"
    word = {"missing": "no such file", "a folder": "is a folder"}.get(name)
    if name == "a folder":
        bad.mkdir()
    elif name != "missing":
        bad.write_bytes(BAD[name][0])
        word = BAD[name][1]
    for order in ((bad, good), (good, bad)):
        out = tmp_path / f"cmp-{order[0].stem}"
        assert cli.main(["benchmark", "--compare", *map(str, order), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--compare" in err[0] and str(bad) in err[0] and word in err[0], err
        assert "Traceback" not in err[0] and not (out / "compare.json").exists()


def test_a_good_document_is_read_and_an_older_version_the_same(tmp_path):
    """A document without results_version (written by dsm 0.2.0) is version 1 and reads as it is;
    NaN rates (undefined) are numbers."""
    doc = {**GOOD, "cases": [{**GOOD["cases"][0], "flip": float("nan")}]}
    (tmp_path / "a.json").write_text(json.dumps(doc))
    assert document.read(tmp_path / "a.json")["cases"][0]["n_acne"] == 3
    assert document.check({**GOOD, "results_version": 2}) is not None


@pytest.mark.parametrize("argv, word", [
    (["--compare", "A", "B", "--cluster", "local"], "--cluster"),
    (["--compare", "A", "B", "--full"], "--full"),
    (["--compare", "A", "B", "--suite", "dsm-bench-1"], "--suite"),
    (["--page", "X", "--full"], "--full"),
    (["--compare", "A", "B", "--size", "test"], "--size"),
    (["--page", "X", "--size", "default"], "--size"),
    (["--size", "test", "--full"], "--size test and --full disagree"),
    (["--out", ""], "--out"),
    (["--cluster", ""], "--cluster"),
    (["--resume", "--force"], "--resume"),
])
def test_flags_that_do_not_apply_are_refused_before_any_work(argv, word, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["benchmark", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0], err
    assert list(tmp_path.iterdir()) == []          # nothing written, not even the default --out


def test_resume_without_an_interrupted_run_and_page_without_results_are_refused(tmp_path, capsys):
    assert cli.main(["benchmark", "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "no interrupted run" in capsys.readouterr().err
    assert cli.main(["benchmark", "--page", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--page" in err and "no such file" in err and not (tmp_path / "leaderboard.html").exists()


FOREIGN = {"a dsm run's folder": ({"run.json": "{}", "metrics.csv": "case\n", "report.html": "<p>"}, "holds a dsm run"),
           "a user's folder": ({"notes.txt": "mine", "thesis/ch1.tex": "x"}, "not a dsm benchmark's")}


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("kind", list(FOREIGN))
def test_benchmark_refuses_a_folder_of_another_commands_files(kind, force, tmp_path, capsys):
    out = tmp_path / "f"
    for name, text in FOREIGN[kind][0].items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(text)
    before = folder_files(out)
    rc, err = cli_lines(capsys, "benchmark", "--out", out, *(["--force"] if force else []))
    assert rc == 2
    one_line(err, f"--out {out}", FOREIGN[kind][1], "choose another --out")
    assert folder_files(out) == before
    (tmp_path / "a.json").write_text(json.dumps(GOOD_V3))
    rc, err = cli_lines(capsys, "benchmark", "--compare", tmp_path / "a.json", tmp_path / "a.json", "--out", out)
    assert rc == 2                   # --compare's compare.json and compare.txt: not among them either
    one_line(err, f"--out {out}", FOREIGN[kind][1])
    assert folder_files(out) == before


def test_benchmark_takes_a_folder_that_holds_only_its_own_compare(tmp_path):
    from dsm.benchmark import command
    out = tmp_path / "benchmark"
    out.mkdir()
    (out / "compare.json").write_text("{}")
    (out / "compare.txt").write_text("")
    assert command.folder_problem(out, force=False, resume=False) is None


def test_benchmark_page_with_out_is_refused(tmp_path, capsys):
    rc, err = cli_lines(capsys, "benchmark", "--page", tmp_path / "a", "--out", tmp_path / "b")
    assert rc == 2
    one_line(err, "--page", "--out does not apply")
    assert list(tmp_path.iterdir()) == []


GOOD_V3 = {"suite": "dsm-bench-4", "suite_sha256": "x", "size": "test", "dsm_version": "0", "versions": {
    "dsm": "0", "mitsuba": "3", "drjit": "1"}, "variant": "llvm_ad_rgb", "machine": {}, "cases": [
    {"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p", "n_receivers": 100,
     "n_acne": 3, "n_peterpan": 1, "flip": 0.01, "error_rate": 0.04, "map_bytes": 1, "page_table_bytes": 0,
     "map_rays": 1, "taps": 1}], "results_version": 3}


def _doc_of_case(**case):
    return {**GOOD_V3, "cases": [{**GOOD_V3["cases"][0], **case}]}


@pytest.mark.parametrize("doc, word", [
    (_doc_of_case(error_rate="0.04"), "cases[0].error_rate is '0.04', not a number"),
    ({**GOOD_V3, "cases": [{k: v for k, v in GOOD_V3["cases"][0].items() if k != "n_receivers"}]}, "has no n_receivers"),
    ({**GOOD_V3, "cases": []}, "cases is empty"),
    ({**GOOD_V3, "cases": GOOD_V3["cases"] * 2}, "cases[1] repeats cases[0]"),
    (_doc_of_case(offset=[1]), "cases[0].offset is a list"),
    (_doc_of_case(error_rate=1.5), "cases[0].error_rate is 1.5, not a rate"),
    (_doc_of_case(n_gt_shadowed="10"), "cases[0].n_gt_shadowed is '10', not a count"),
])
def test_page_and_compare_refuse_a_damaged_document_in_one_line(doc, word, tmp_path, capsys):
    folder = tmp_path / "b"
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps(doc))
    before = folder_files(folder)
    rc, err = cli_lines(capsys, "benchmark", "--page", folder)
    assert rc == 2
    one_line(err, "--page", str(folder / "results.json"), word)
    assert folder_files(folder) == before
    (tmp_path / "good.json").write_text(json.dumps(GOOD_V3))
    rc, err = cli_lines(capsys, "benchmark", "--compare", tmp_path / "good.json", folder / "results.json",
                      "--out", tmp_path / "cmp")
    assert rc == 2
    one_line(err, "--compare", word)
    assert not (tmp_path / "cmp" / "compare.json").exists()


@pytest.mark.parametrize("a, b, changed", [(0.01, float("nan"), 1), (float("nan"), 0.01, 1),
                                           (float("nan"), float("nan"), 0), (0.01, 0.0105, 0)])
def test_compare_counts_a_flip_that_became_undefined_as_changed(a, b, changed):
    diff = compare.compare(_doc_of_case(flip=a), _doc_of_case(flip=b))
    assert (len(diff["changed"]), diff["n_tied"]) == (changed, 1 - changed)


def _record(**over) -> dict:
    rec = {"scene": "s", "unit": "m", "light": "directional", "contender": "p", "n_receivers": 795,
           "n_gt_shadowed": 40, "n_acne": 21, "n_peterpan": 4}
    rec.update(over)
    n, sh = rec["n_receivers"], rec["n_gt_shadowed"]
    rates = {"acne_rate": rec["n_acne"] / (n - sh), "peterpan_rate": rec["n_peterpan"] / sh,
             "error_rate": (rec["n_acne"] + rec["n_peterpan"]) / n}
    return {**rec, **rates, **over}


@pytest.mark.parametrize("edit", [{}, {"n_acne": 99999}, {"error_rate": 0.5}, {"n_peterpan": 41}, {"n_acne": -1},
                                  {"n_receivers": 10}])
def test_a_kept_case_edited_to_impossible_counts_runs_again(edit, tmp_path):
    from types import SimpleNamespace
    log = caselog.CaseLog(tmp_path, {"suite": "dsm-bench-4"})
    log.start(resume=False)
    log.keep(0, SimpleNamespace(scene="s", unit="m", offset="0"), [_record(**edit)], [], "llvm_ad_rgb")
    log.keep(1, SimpleNamespace(scene="t", unit="m", offset="0"), [_record(), {"contender": "oracle",
                                                                               "n_receivers": 3}], [], "llvm_ad_rgb")
    assert sorted(log.finished()) == ([0, 1] if not edit else [1])


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


def _edited_doc(edit: dict) -> dict:
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
    (folder / "results.json").write_text(json.dumps(_edited_doc(edit)))
    (tmp_path / "good.json").write_text(json.dumps(DOC))
    before = folder_files(tmp_path)
    rc, err = cli_run(capsys, "benchmark", "--page", folder)
    assert rc == 2
    one_line(err, "--page", str(folder / "results.json"), *words)
    rc, err = cli_run(capsys, "benchmark", "--compare", tmp_path / "good.json", folder / "results.json",
                      "--out", tmp_path / "cmp")
    assert rc == 2
    one_line(err, "--compare", *words)
    assert folder_files(tmp_path) == before and not (tmp_path / "cmp").exists()


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
