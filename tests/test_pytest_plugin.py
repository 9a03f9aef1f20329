"""dsm's pytest plugin (dsm/pytest_plugin.py) under pytest-xdist: a config that two workers ask for runs
once, the second worker reading the first's Results; without xdist nothing is shared. And the suite's
own grouping under xdist (tests/conftest.py): the tests that share a module fixture run in one worker."""
import os
import subprocess
import sys

import pytest

from conftest import ROOT, shared_fixture_users

# counts every dsm.run, one line per call naming the process's worker, in the file COUNT_FILE names
COUNTING_CONFTEST = '''
import os
import dsm

real_run = dsm.run


def counted_run(*args, **kwargs):
    with open(os.environ["COUNT_FILE"], "a") as fh:
        fh.write(os.environ.get("PYTEST_XDIST_WORKER", "alone") + "\\n")
    return real_run(*args, **kwargs)


dsm.run = counted_run
'''

# one test that asks for a config and writes what it got, in a file named after its worker
ASKING_TEST = '''
import json
import os

CFG = {"experiment": {"name": "shared"}, "camera": {"resolution": [24, 24]}, "scene": [{"builtin": "plane_box"}],
       "map": {"resolution": 32}, "scheme": [{"name": "none"}, {"name": "constant"}], "timing": {"repeats": 1}}


def test_ask(dsm_results):
    res = dsm_results(CFG)
    again = dsm_results(dict(CFG))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "alone")
    seen = {"same_object": again is res, "out": str(res.out),
            "rows": [{k: r[k] for k in ("case", "scheme", "n_receivers", "n_acne", "n_peterpan")} for r in res.rows]}
    with open(os.path.join(os.environ["SEEN_DIR"], worker + ".json"), "w") as fh:
        json.dump(seen, fh)
'''


def _pytest(tmp_path, *args):
    """Run pytest on the two generated files in tmp_path/t (this checkout's dsm first on the path)."""
    import json
    suite = tmp_path / "t"
    suite.mkdir()
    (suite / "conftest.py").write_text(COUNTING_CONFTEST)
    (suite / "test_ask.py").write_text(ASKING_TEST)
    env = {**os.environ, "COUNT_FILE": str(tmp_path / "runs.txt"), "SEEN_DIR": str(tmp_path)}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "plugins"), env.get("PYTHONPATH", "")])
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT", "PYTEST_ADDOPTS"):   # this run's own, if any
        env.pop(name, None)
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--basetemp",
                        str(tmp_path / "base"), *args, str(suite)], capture_output=True, text=True, env=env,
                       cwd=suite, timeout=600)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    runs = (tmp_path / "runs.txt").read_text().split()
    seen = {f.stem: json.loads(f.read_text()) for f in tmp_path.glob("*.json")}
    return runs, seen


@pytest.mark.slow
def test_two_xdist_workers_asking_for_one_config_run_it_once(tmp_path):
    """--dist each: both workers run the one test, so both ask for the config; one runs it, the
    other waits on the lock and reads the same rows (from the same folder)."""
    pytest.importorskip("xdist", reason="pytest-xdist is part of the test extra (pip install -e .[test])")
    runs, seen = _pytest(tmp_path, "-n", "2", "--dist", "each")
    assert sorted(seen) == ["gw0", "gw1"], seen.keys()
    assert len(runs) == 1 and runs[0] in seen, runs
    assert seen["gw0"]["rows"] == seen["gw1"]["rows"] and len(seen["gw0"]["rows"]) == 2
    assert seen["gw0"]["out"] == seen["gw1"]["out"]
    assert seen["gw0"]["same_object"] and seen["gw1"]["same_object"]   # within a worker, one object
    assert (tmp_path / "base" / "dsm-results").is_dir()


@pytest.mark.slow
def test_without_xdist_the_plugin_shares_nothing(tmp_path):
    """One process: the config runs once, as before xdist, and no shared folder is made beside the session's."""
    runs, seen = _pytest(tmp_path)
    assert runs == ["alone"] and sorted(seen) == ["alone"] and seen["alone"]["same_object"]
    assert not (tmp_path / "dsm-results").exists() and not (tmp_path / "base" / "dsm-results").exists()


SHARING_FILE = """
import pytest

@pytest.fixture(scope="module")
def site():
    return 1

@pytest.fixture(scope="class", name="page")
def a_page_fixture():
    return 2

@pytest.fixture
def built(site):                  # a function fixture that takes the module one shares it
    return site

@pytest.fixture
def fresh(tmp_path):
    return tmp_path

def test_site(site): pass
def test_page(page, tmp_path): pass
def test_built(built): pass
def test_fresh(fresh): pass
def test_alone(): pass
"""


def test_the_tests_taking_a_module_or_class_fixture_of_their_file_are_found(tmp_path):
    """Directly, under a fixture's own name, through a function fixture; not a plain test or one whose
    fixtures are all function-scoped; every test where a shared fixture is autouse."""
    (tmp_path / "test_x.py").write_text(SHARING_FILE)
    assert shared_fixture_users(tmp_path / "test_x.py") == {"test_site", "test_page", "test_built"}
    (tmp_path / "test_y.py").write_text(SHARING_FILE.replace('(scope="module")', '(scope="module", autouse=True)'))
    assert shared_fixture_users(tmp_path / "test_y.py") == {"test_site", "test_page", "test_built", "test_fresh",
                                                               "test_alone"}
    (tmp_path / "test_z.py").write_text(SHARING_FILE.replace('scope="module"', 'scope="function"')
                                        .replace('scope="class", ', ""))
    assert shared_fixture_users(tmp_path / "test_z.py") == set()


# the suite's scheduler hook, taken from tests/conftest.py into a generated suite's conftest
SCHEDULER_CONFTEST = '''
import importlib.util

spec = importlib.util.spec_from_file_location("dsm_suite_conftest", {conftest!r})
suite = importlib.util.module_from_spec(spec)
spec.loader.exec_module(suite)
pytest_xdist_make_scheduler = suite.pytest_xdist_make_scheduler
'''

# a module fixture that notes each build (and its worker); users and non-users interleaved
BUILDS_TEST = '''
import os
import pytest


@pytest.fixture(scope="module")
def expensive():
    with open(os.environ["BUILDS_FILE"], "a") as fh:
        fh.write(os.environ.get("PYTEST_XDIST_WORKER", "alone") + "\\n")
    return 1


@pytest.mark.parametrize("i", range(6))
def test_user(expensive, i):
    assert expensive == 1


@pytest.mark.parametrize("i", range(6))
def test_other(i):
    pass
'''


@pytest.mark.slow
def test_the_tests_sharing_a_module_fixture_run_in_one_worker_which_builds_it_once(tmp_path):
    """-n 2 --dist loadgroup with the suite's scheduler: the module fixture is built once; with xdist's own
    loadgroup scheduler each test is its own unit, dealt out in turn, and both workers build it."""
    pytest.importorskip("xdist", reason="pytest-xdist is part of the test extra (pip install -e .[test])")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "plugins"), os.environ.get("PYTHONPATH", "")])}
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT", "PYTEST_ADDOPTS"):
        env.pop(name, None)
    runs = {}
    # the two suites run side by side (a folder, a conftest and a builds file each): neither reads the other's
    for label, conftest in (("ours", SCHEDULER_CONFTEST.format(conftest=str(ROOT / "tests" / "conftest.py"))),
                            ("xdist's", "")):
        suite = tmp_path / ("t-ours" if label == "ours" else "t-xdist")
        suite.mkdir()
        (suite / "test_builds.py").write_text(BUILDS_TEST.replace("test_other", "test_zz_other"))
        (suite / "conftest.py").write_text(conftest)
        runs[label] = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2",
                                        "--dist", "loadgroup", "-p", "no:dsm", str(suite)], stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True, cwd=suite,
                                       env={**env, "BUILDS_FILE": str(tmp_path / f"builds-{label}.txt")})
    builds = {}
    try:
        for label, proc in runs.items():
            out, err = proc.communicate(timeout=300)
            assert proc.returncode == 0, out[-3000:] + err[-3000:]
            builds[label] = (tmp_path / f"builds-{label}.txt").read_text().split()
    finally:                          # a failed or timed-out one leaves no pytest behind
        for proc in runs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert len(builds["ours"]) == 1, builds
    assert sorted(builds["xdist's"]) == ["gw0", "gw1"], builds     # the check above can fail
