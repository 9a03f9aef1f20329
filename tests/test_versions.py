"""The versions a result depends on (dsm's, Mitsuba's, Dr.Jit's): recorded in run.json and results.json,
part of every case's resume key, and named in one line by --resume and --compare when they differ."""
import json
import os
from importlib.metadata import version

import drjit as dr
import mitsuba as mi
import pytest

import dsm
from dsm import cli
from dsm.benchmark import caselog, document
from dsm.benchmark.suite import LATEST, SUITE_FILES, cases, load_suite, suite_sha256
from dsm.config import plan as planmod
from dsm.config import read as cfgmod
from dsm.core import env
from dsm.experiment import resume

CONFIG = {"experiment": {"name": "versions"}, "camera": {"resolution": [24, 24]}, "scene": [{"builtin": "plane_box"}],
          "light": [{"type": "directional", "direction": [-0.4, -0.3, -1.0]}], "map": {"resolution": 24},
          "scheme": [{"name": "none"}, {"name": "constant", "bias": [0.01, 0.05]}], "timing": {"repeats": 1}}


def test_versions_name_the_installed_packages():
    """What is recorded is what pip installed (package metadata), and dsm's own version is pyproject's."""
    v = env.versions()
    assert (v["mitsuba"], v["drjit"], v["dsm"]) == (version("mitsuba"), version("drjit"), version("dsm"))
    assert (v["mitsuba"], v["drjit"]) == (mi.__version__, dr.__version__) and v["dsm"] == dsm.__version__
    assert env.engine(v) == {"dsm": v["dsm"], "mitsuba": v["mitsuba"], "drjit": v["drjit"]}


def test_engine_change_names_each_moved_version_and_nothing_when_equal():
    a = {"dsm": "0.3.0", "mitsuba": "3.9.0", "drjit": "1.4.0", "python": "3.11.7", "dsm_git_commit": "x"}
    assert env.engine_change(a, {**a, "python": "3.12.1", "dsm_git_commit": "y"}) is None   # not an engine version
    assert env.engine_change(a, {**a, "mitsuba": "3.9.1", "drjit": "1.5.0"}) == \
        "mitsuba 3.9.0 -> 3.9.1, drjit 1.4.0 -> 1.5.0"
    assert env.engine_change({"mitsuba": "3.9.0", "drjit": "1.4.0"}, a) == "dsm unrecorded -> 0.3.0"


def test_dr_jit_1_0_s_libllvm_version_as_text_is_read(monkeypatch):
    """Dr.Jit 1.0 returns the version as "19.1.7", later releases as a tuple: both read as numbers."""
    monkeypatch.setattr(dr.detail, "llvm_version", lambda: "16.0.6")
    assert env.llvm_version() == (16, 0, 6)
    monkeypatch.setattr(dr.detail, "llvm_version", lambda: (19, 1, 7))
    assert env.llvm_version() == (19, 1, 7)


@pytest.mark.parametrize("key", ["mitsuba", "drjit", "dsm"])
def test_a_case_key_changes_with_each_engine_version(key):
    cfg = cfgmod.coerce(CONFIG)
    plan = planmod.make(cfg)
    v = {"dsm": "0.3.0", "mitsuba": "3.9.1", "drjit": "1.5.0", "dsm_git_commit": "abc", "python": "3.11.7"}
    same = resume.case_keys(cfg, plan, resume.kit_version(v))
    assert same == resume.case_keys(cfg, plan, resume.kit_version({**v, "python": "3.12.0"}))
    other = resume.case_keys(cfg, plan, resume.kit_version({**v, key: "9.9.9"}))
    assert [c for c, _ in other] == [c for c, _ in same] and all(a != b for (_, a), (_, b) in zip(same, other))


@pytest.mark.slow
def test_resume_with_other_versions_says_so_in_one_line_and_runs_every_case_again(tmp_path, monkeypatch, capsys):
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    real = env.versions()
    out = tmp_path / "o"
    with monkeypatch.context() as mp:                # the folder's run, as measured on Mitsuba 3.0.0
        mp.setattr(env, "versions", lambda: {**real, "mitsuba": "3.0.0"})
        first = Runner(pipeline.prepare(CONFIG), out, progress=False).run()
    assert first.run["versions"]["mitsuba"] == "3.0.0"
    capsys.readouterr()
    again = Runner(pipeline.prepare(CONFIG), out, progress=False, resume_previous=True).run()
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("dsm: --resume")]
    assert err == [f"dsm: --resume: {out} was measured with other versions (mitsuba 3.0.0 -> {mi.__version__}); "
                   "results differ bit for bit between versions, so its cases run again"]
    assert again.run["resumed_cases"] == 0 and len(again.rows) == len(first.rows) == 3
    assert again.run["versions"]["mitsuba"] == mi.__version__
    third = Runner(pipeline.prepare(CONFIG), out, progress=False, resume_previous=True).run()
    assert third.run["resumed_cases"] == 3                   # same versions: every case kept, nothing said
    assert not [line for line in capsys.readouterr().err.splitlines() if line.startswith("dsm: --resume")]


def _bench_header(size: str, versions: dict) -> dict:
    """The header of a benchmark run in progress, as `dsm benchmark --out X` writes it at ``size``."""
    s = load_suite(SUITE_FILES[LATEST])
    return {"suite": s["suite"]["name"], "suite_sha256": suite_sha256(SUITE_FILES[LATEST]), "size": size,
            "variant": None, "cluster": None, "cases": len(cases(s, size)), "versions": versions}


def test_benchmark_resume_on_other_versions_is_refused_in_one_line(tmp_path, capsys):
    """A benchmark run in progress made with another Dr.Jit: --resume names the versions, exit 2, no case run."""
    out = tmp_path / "bm"
    here = env.engine(env.versions())
    caselog.CaseLog(out, _bench_header("test", {**here, "drjit": "1.0.0"})).start(False)
    assert cli.main(["benchmark", "--out", str(out), "--size", "test", "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dsm benchmark: --out {out}: cannot resume: its run in progress was measured with other versions (drjit "
                   f"1.0.0 -> {dr.__version__}); results differ bit for bit between versions; --force starts again"]
    assert sorted(p.name for p in (out / "cases").iterdir()) == ["run.json"]
    assert json.loads((out / "cases" / "run.json").read_text())["versions"]["drjit"] == "1.0.0"   # kept as it was
    # the same versions (and suite, size, variant, backend): the run in progress is the one to go on with
    assert caselog.CaseLog(out, _bench_header("test", {**here, "drjit": "1.0.0"})).finished() == {}


def _doc(mitsuba: str) -> dict:
    rec = {"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p", "n_receivers": 100,
           "n_acne": 3, "n_peterpan": 1}
    return {"results_version": 3, "suite": "dsm-bench-4", "suite_sha256": "x", "cases": [rec],
            "versions": {"dsm": "0.3.0", "mitsuba": mitsuba, "drjit": "1.5.0", "dsm_git_commit": "c"}}


def test_compare_says_in_one_line_when_versions_differ(tmp_path, capsys):
    for name, mitsuba in (("a", "3.9.0"), ("b", "3.9.1"), ("c", "3.9.1")):
        (tmp_path / f"{name}.json").write_text(json.dumps(_doc(mitsuba)))
    said = []
    for a, b in (("a", "b"), ("b", "c")):
        assert cli.main(["benchmark", "--compare", str(tmp_path / f"{a}.json"), str(tmp_path / f"{b}.json"),
                         "--out", str(tmp_path / f"cmp-{a}{b}")]) == 0
        said.append([line for line in capsys.readouterr().out.splitlines() if "versions" in line])
    assert said[0] == ["versions differ: mitsuba 3.9.0 -> 3.9.1 (results differ bit for bit between versions: a "
                       "change may be theirs)"]
    assert said[1] == []
    diff = json.loads((tmp_path / "cmp-ab" / "compare.json").read_text())
    assert diff["versions_change"] == "mitsuba 3.9.0 -> 3.9.1" and diff["n_tied"] == 1


@pytest.mark.parametrize("versions, word", [(None, "versions is null"), ({"dsm": "0.3.0", "mitsuba": "3.9.1"},
                                                                         "versions.drjit")])
def test_a_version_3_document_must_name_its_versions(versions, word):
    doc = _doc("3.9.1")
    doc["versions"] = versions
    with pytest.raises(document.NotResults, match=word):
        document.check(doc, "r.json")
    older = {**doc, "results_version": 2}        # version 2 did not require them, but given, an object
    if isinstance(versions, dict):
        assert document.check(older) is not None
    else:
        with pytest.raises(document.NotResults, match="versions is null, not an object"):
            document.check(older, "r.json")
    assert document.check({k: v for k, v in older.items() if k != "versions"}) is not None


def test_a_dsm_copy_inside_another_projects_repository_records_no_commit_of_that_repository(tmp_path):
    """git_commit asks git from the package's folder: a dsm copied into another project's repository
    (a vendored or installed copy) is not that repository's commit, and says ``unknown``; the
    checkout itself names its own HEAD."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path
    from dsm.core import env
    root = Path(env.__file__).resolve().parents[2]
    other = tmp_path / "other"
    shutil.copytree(root / "dsm", other / "lib" / "dsm", ignore=shutil.ignore_patterns("__pycache__"))
    git = lambda *a: subprocess.run(["git", *a], cwd=other, capture_output=True, text=True, check=True).stdout
    git("init", "-q")
    git("-c", "user.email=a@b", "-c", "user.name=a", "commit", "-q", "--allow-empty", "-m", "x")
    code = "from dsm.core import env; print(env.git_commit())"
    got = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(other / "lib")}).stdout.strip()
    assert got == "unknown"
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True).stdout.strip()
    assert env.git_commit().split("+")[0] == head
