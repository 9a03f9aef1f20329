"""dsm benchmark's answers to bad input: every --compare file that is not a results document, and
flags that do not apply, get one line naming the file or flag, exit 2, and nothing written."""
import json

import pytest

from dsm import cli
from dsm.benchmark import document

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
