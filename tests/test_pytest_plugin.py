"""dsm's pytest plugin (dsm/pytest_plugin.py) under pytest-xdist: a config that two workers ask for runs
once, the second worker reading the first's Results; without xdist nothing is shared."""
import os
import subprocess
import sys

import pytest

from conftest import ROOT

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
