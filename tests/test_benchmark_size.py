"""dsm benchmark --size: its help counts each size's cases and contenders as the suite's TOML defines them
(counted here a second way, from the TOML's tables), the size reaches the run, and the old spellings
(--full, DSM_BENCHMARK_SIZE) work as aliases that say so, or are refused in one line where they disagree."""
import re
import tomllib

import pytest

from dsm import cli
from dsm.benchmark import caselog, command
from dsm.benchmark.suite import LATEST, SUITE_FILES, cases, load_suite, suite_sha256
from dsm.core import env

SIZES = ("test", "default", "full")


def _toml_counts(size: str) -> tuple:
    """(cases, contenders) of the newest suite at ``size``, from its TOML alone: every scene at each unit,
    and at each far offset unless ``far = false``; the depth contenders, each pre-filtered kind at its
    defaults and presets per blur, the virtual presets where the directional light runs, and the hybrid ones."""
    toml = tomllib.loads(SUITE_FILES[LATEST].read_text())
    table, c, pre = toml["size"][size], toml["contenders"], toml["prefiltered"]
    names = table.get("scenes", [sc["name"] for sc in toml["scene"]])
    units = table.get("units", [u for u, _ in toml["suite"]["units"]])
    far = [o for o in table.get("offsets", [o for o, _ in toml["suite"]["offsets"]]) if o != "0"]
    n_cases = sum(len(units) + len(far) * sc.get("far", True) for sc in toml["scene"] if sc["name"] in names)
    depth = table.get("contenders", c["presets"] + c["schemes"] + list(c["tuned"]))
    kinds = table.get("prefiltered", pre["kinds"])
    n_pre = sum(1 + len(pre["presets"].get(k, [])) for k in kinds) * len(pre["blur"])
    n_virtual = len(toml["virtual"]["presets"]) * ("directional" in table.get("lights", ["directional"]))
    n_hybrid = len(toml["hybrid"]["contender"])
    return n_cases, len(depth) + n_pre + n_virtual + n_hybrid


def _help_counts(capsys) -> dict:
    """size -> (cases, contenders, its time in words) as ``dsm benchmark --help`` prints them."""
    assert cli.main(["benchmark", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    sizes = text.split("--size), with the wall time of a run on 2 cores:", 1)[1]
    line = r" (test|default|full) (\d+) cases \(.*?\), .*?, (\d+) contenders, .*?; (.*?)(?= default | full |$)"
    found = re.findall(line, sizes)
    return {size: (int(n), int(k), words) for size, n, k, words in found}


def test_help_counts_each_size_as_the_suite_defines_it(capsys):
    counts = _help_counts(capsys)
    assert list(counts) == list(SIZES)
    for size in SIZES:
        assert counts[size][:2] == _toml_counts(size), size
    assert counts["test"][:2] == (8, 12) and counts["default"][:2] == (45, 33)   # the documented sizes
    for size, (_, _, words) in counts.items():      # a time as measured, or that it was not
        assert re.fullmatch(r"about \d+ (s|minutes) quiet, \d+ (s|minutes) with other jobs beside|"
                            r"about \d+ (s|minutes) with other jobs beside \(not measured quiet\)|"
                            r"not measured on 2 cores.*", words), (size, words)
    assert counts["test"][2] == "about 62 s with other jobs beside (not measured quiet)"
    assert counts["full"][2].startswith("not measured")


def test_measured_times_name_only_known_suites_and_sizes():
    for version, by_size in command.MEASURED_WALL_S.items():
        assert version in SUITE_FILES and set(by_size) <= set(SIZES)
        assert all((quiet_s is None or 0 < quiet_s <= loaded_s) and loaded_s > 0
                   for quiet_s, loaded_s in by_size.values())


@pytest.fixture
def started(monkeypatch, tmp_path):
    """The size each run reaches (the run itself replaced: nothing is measured)."""
    sizes = []
    monkeypatch.setattr(command, "_run", lambda args, out, size: sizes.append(size) or 0)
    monkeypatch.delenv(command.SIZE_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    return sizes


FULL = "--full is an alias for --size full (kept for old scripts): give --size full"
ENV_TEST = "DSM_BENCHMARK_SIZE is deprecated, an alias for --size test: give --size test"


@pytest.mark.parametrize("argv, env, size, alias", [
    ([], None, "default", None),
    (["--size", "test"], None, "test", None),
    (["--size", "full"], None, "full", None),
    (["--full"], None, "full", FULL),
    (["--size", "full", "--full"], None, "full", FULL),
    ([], "test", "test", ENV_TEST),
    (["--size", "test"], "test", "test", ENV_TEST),
])
def test_the_size_reaches_the_run_and_an_old_spelling_says_it_is_an_alias(argv, env, size, alias, started,
                                                                          monkeypatch, capsys):
    if env:
        monkeypatch.setenv(command.SIZE_ENV, env)
    assert cli.main(["benchmark", "--out", "bm", *argv]) == 0
    assert started == [size]
    assert capsys.readouterr().err.strip().splitlines() == ([f"dsm benchmark: {alias}"] if alias else [])


@pytest.mark.parametrize("argv, env, says", [
    (["--size", "default"], "test", "--size default and DSM_BENCHMARK_SIZE=test disagree: give one --size"),
    (["--full"], "test", "--full and DSM_BENCHMARK_SIZE=test disagree: give one --size"),
    ([], "huge", "DSM_BENCHMARK_SIZE=huge: not a size (one of test, default, full); give --size"),
])
def test_a_size_given_two_ways_that_disagree_is_refused_in_one_line(argv, env, says, started, monkeypatch, capsys,
                                                                     tmp_path):
    monkeypatch.setenv(command.SIZE_ENV, env)
    assert cli.main(["benchmark", "--out", "bm", *argv]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"dsm benchmark: {says}"]
    assert started == [] and list(tmp_path.iterdir()) == []       # before any work: not even --out


def test_resume_at_another_size_is_refused_naming_the_size(tmp_path, capsys, monkeypatch):
    """A run in progress at the test size: --resume at the default size (no --size) names the size, not the number
    of cases that follows from it; nothing is run."""
    monkeypatch.delenv(command.SIZE_ENV, raising=False)
    out, s = tmp_path / "bm", load_suite(SUITE_FILES[LATEST])
    header = {"suite": LATEST, "suite_sha256": suite_sha256(SUITE_FILES[LATEST]), "size": "test", "variant": None,
              "cluster": None, "cases": len(cases(s, "test")), "versions": env.engine(env.versions())}
    caselog.CaseLog(out, header).start(False)
    assert cli.main(["benchmark", "--out", str(out), "--resume"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"dsm benchmark: --out {out}: cannot resume: its run in progress has size = 'test', this run 'default'; "
        "--force starts again"]
    assert sorted(p.name for p in (out / "cases").iterdir()) == ["run.json"]
