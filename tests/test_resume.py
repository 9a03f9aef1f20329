"""Resumable runs: a run killed with SIGKILL resumes to the rows of an uninterrupted run; an
edited config reruns only the cases whose identity changed and lists (keeps) the stale ones."""
import csv
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import VARYING, cli_lines
from dsm.report import figures

ROOT = __import__("pathlib").Path(__file__).resolve().parent.parent

CONFIG = """
[experiment]
name = "resume"
[camera]
resolution = [40, 40]
[[scene]]
builtin = "plane_box"
[[light]]
type = "directional"
direction = [-0.4, -0.3, -1.0]
[map]
resolution = [24, 32]
[timing]
repeats = 1
[[scheme]]
name = "none"
[[scheme]]
name = "constant"
bias = [0.001, 0.003, 0.01, 0.03, 0.1]
[[scheme]]
name = "slope_scaled"
[[scheme]]
name = "midpoint"
"""


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _counts(rows):
    return [{k: v for k, v in r.items() if k not in VARYING} for r in rows]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "plugins"), env.get("PYTHONPATH", "")])
    return env


def _dsm(capsys, *args) -> tuple:
    """(exit status, stderr) of ``dsm args`` called in-process (the process is not what these tests test)."""
    rc, err = cli_lines(capsys, *args)
    return rc, "\n".join(err)


@pytest.mark.slow
def test_a_killed_run_resumes_to_the_rows_of_an_uninterrupted_run(tmp_path, capsys):
    """The run killed (SIGKILL) is a process of its own; the runs before and after it are called in-process."""
    cfg = tmp_path / "resume.toml"
    # cases enough that the kill lands while measuring, not in the report after it (a case is ~5 ms)
    biases = ", ".join(f"{0.001 * k:g}" for k in range(1, 21))
    cfg.write_text(CONFIG.replace("resolution = [24, 32]", "resolution = [24, 32, 48, 64, 96, 128]")
                   .replace("bias = [0.001, 0.003, 0.01, 0.03, 0.1]", f"bias = [{biases}]"))
    rc, err = _dsm(capsys, "run", cfg, "--out", tmp_path / "whole")
    assert rc == 0, err[-2000:]
    total = len(_rows(tmp_path / "whole" / "metrics.csv"))
    assert total == 6 * 23

    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "dsm", "run", str(cfg), "--out", str(out)], env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        # rows are written as cases finish, run.json at most once a second: kill between the two
        if (out / "metrics.csv").is_file() and len((out / "metrics.csv").read_text().splitlines()) > 3:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    killed = json.loads((out / "run.json").read_text())
    rows_killed = len(_rows(out / "metrics.csv"))
    assert killed["state"] == "running" and killed["n_cases_ok"] <= rows_killed < total

    # without --resume or --force the folder is refused as before
    rc, err = _dsm(capsys, "run", cfg, "--out", out)
    assert rc == 2 and "--force" in err
    rc, err = _dsm(capsys, "run", cfg, "--out", out, "--resume")
    assert rc == 0, err[-2000:]
    run = json.loads((out / "run.json").read_text())
    assert run["state"] == "complete" and run["stale_cases"] == []
    # exactly the cases run.json listed are kept; those finished after its last write run again
    assert run["resumed_cases"] == killed["n_cases_ok"]
    assert _counts(_rows(out / "metrics.csv")) == _counts(_rows(tmp_path / "whole" / "metrics.csv"))
    for r in _rows(out / "metrics.csv"):
        assert (out / figures.image_paths(r)[0]).is_file()
    # a second resume of a complete run runs nothing again
    assert _dsm(capsys, "run", cfg, "--out", out, "--resume")[0] == 0
    assert json.loads((out / "run.json").read_text())["resumed_cases"] == total


def _cfg(biases, schemes=("none", "constant")):
    sch = [{"name": "none"}] if "none" in schemes else []
    sch.append({"name": "constant", "bias": list(biases)})
    return {"experiment": {"name": "edit"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane_box"}],
            "light": [{"type": "directional", "direction": [-0.4, -0.3, -1.0]}], "map": {"resolution": 32}, "scheme": sch, "timing": {"repeats": 1}}


@pytest.mark.slow
def test_an_edited_config_reruns_changed_cases_and_lists_stale_ones(tmp_path):
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    out = tmp_path / "o"
    first = Runner(pipeline.prepare(_cfg([0.01, 0.05])), out, progress=False).run()
    assert [r["case"] for r in first.rows] == ["0001", "0002", "0003"]
    keys = {s["what"]: s["key"] for s in first.run["status"] if s["what"].startswith("case")}
    # drop "none", keep bias 0.05, add bias 0.2: one kept (now case 0001), one new, two stale
    res = Runner(pipeline.prepare(_cfg([0.05, 0.2], ("constant",))), out, progress=False,
                 resume_previous=True).run()
    assert res.run["resumed_cases"] == 1
    assert sorted(s["case"] for s in res.run["stale_cases"]) == ["0001", "0002"]
    assert {s["key"] for s in res.run["stale_cases"]} == {keys["case 0001"], keys["case 0002"]}
    rows = _rows(out / "metrics.csv")
    assert [(r["case"], r["params"]) for r in rows] == [("0001", "bias=0.05"), ("0002", "bias=0.2")]
    Runner(pipeline.prepare(_cfg([0.05, 0.2], ("constant",))), tmp_path / "fresh", progress=False).run()
    assert _counts(rows) == _counts(_rows(tmp_path / "fresh" / "metrics.csv"))
    # the stale cases' images are kept aside, the kept case's images follow its new id
    folder = figures.image_folder(rows[0])           # images/<scene>_<light>/
    assert sorted(str(p.relative_to(out / "images" / "stale")) for p in (out / "images" / "stale").rglob("*.png")) \
        == [f"{folder}/{n}" for n in ("0001_error.png", "0001_shadow.png", "0002_error.png", "0002_shadow.png")]
    assert (out / figures.image_paths(rows[0])[0]).read_bytes() == \
        (tmp_path / "fresh" / figures.image_paths(rows[0])[0]).read_bytes()


def test_a_case_key_changes_with_its_input_file_and_the_kit_version(tmp_path):
    from dsm.config import read as cfgmod
    from dsm.config import plan as planmod
    from dsm.experiment import resume
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    raw = {"experiment": {"name": "k"}, "scene": [{"file": str(mesh)}], "light": [{"type": "directional",
           "direction": [0, 0, -1]}], "map": {"resolution": 16}, "scheme": [{"name": "none"}]}
    cfg = cfgmod.coerce(raw)
    a = resume.case_keys(cfg, planmod.make(cfg), "v1")
    assert a == resume.case_keys(cfg, planmod.make(cfg), "v1")
    assert a != resume.case_keys(cfg, planmod.make(cfg), "v2")
    mesh.write_text("v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n")
    assert a != resume.case_keys(cfg, planmod.make(cfg), "v1")


@pytest.mark.slow
@pytest.mark.parametrize("flags", [["--resume", "--force"]])
def test_resume_and_force_exclude_each_other(tmp_path, capsys, flags):
    rc, err = _dsm(capsys, "run", "--out", tmp_path / "x", *flags)
    assert rc == 2 and "not allowed with" in err and not (tmp_path / "x").exists()


@pytest.mark.slow
def test_resume_into_another_experiments_folder_is_refused_and_changes_nothing(tmp_path, capsys):
    """--resume with a config of another [experiment] name would set every case of the folder
    aside as stale: exit 2 naming --resume and both experiments, before any work."""
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    out = tmp_path / "o"
    Runner(pipeline.prepare(_cfg([0.01])), out, progress=False).run()
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    other = tmp_path / "other.toml"
    other.write_text(CONFIG.replace('name = "resume"', 'name = "another"'))
    rc, err = _dsm(capsys, "run", other, "--out", out, "--resume")
    assert rc == 2 and "Traceback" not in err, err
    assert err.startswith(f"dsm: --resume: {out} holds experiment 'edit'") and "'another'" in err
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
