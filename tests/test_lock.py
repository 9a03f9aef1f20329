"""One writer per results folder (dsm/experiment/lock.py): an OS lock that a SIGKILL releases, refused in one
line naming the holder's pid, taken by the API as by the command line."""
import json
import os
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import dsm
from conftest import cli_run as _cli, one_line as _one_line, metrics_rows, tiny_toml
from dsm.config import read as config
from dsm.config.read import ConfigError
from dsm.experiment import lock


# holds flock on <folder>/.dsm-lock as any process could, writes its pid there, then waits
HOLDER = ("import fcntl, os, sys, time\n"
          "d = sys.argv[1]; os.makedirs(d, exist_ok=True)\n"
          "fd = os.open(os.path.join(d, '.dsm-lock'), os.O_RDWR | os.O_CREAT)\n"
          "fcntl.flock(fd, fcntl.LOCK_EX)\n"
          "os.ftruncate(fd, 0); os.write(fd, str(os.getpid()).encode())\n"
          "print('held', flush=True); time.sleep(600)\n")


class Holder:
    """A second process holding ``folder``'s lock until killed with SIGKILL."""

    def __init__(self, folder: Path):
        self.proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "held"
        self.pid = self.proc.pid

    def kill(self):
        os.kill(self.pid, signal.SIGKILL)
        assert self.proc.wait(timeout=30) == -signal.SIGKILL


@pytest.fixture
def holder():
    made = []

    def hold(folder):
        made.append(Holder(folder))
        return made[-1]
    yield hold
    for h in made:
        if h.proc.poll() is None:
            h.kill()


@pytest.mark.slow
@pytest.mark.parametrize("flag", [None, "--resume", "--force"])
def test_a_run_into_a_held_folder_is_refused_naming_the_holder_and_free_after_sigkill(tmp_path, capsys, cfg_file,
                                                                                       holder, flag):
    out = tmp_path / "o"
    if flag:                                  # --resume and --force act on a previous run
        assert _cli(capsys, "run", cfg_file, "--out", out)[0] == 0
        before = (out / "metrics.csv").read_bytes()
    h = holder(out)
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, *([flag] if flag else []))
    assert rc == 2
    _one_line(err, str(out), f"process {h.pid}", "in use")
    if flag:
        assert (out / "metrics.csv").read_bytes() == before          # nothing written or cleared
    h.kill()                                  # the OS drops the lock; the lock file stays behind
    assert (out / ".dsm-lock").is_file()
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, *([flag] if flag else []))
    assert rc == 0, err
    assert len(metrics_rows(out)) == 1 and not (out / ".dsm-lock").exists()


def test_tune_bench_and_report_refuse_a_held_folder(tmp_path, capsys, holder):
    tune_cfg = tmp_path / "t.toml"
    tune_cfg.write_text(tiny_toml('[tune]\nsteps = 2\n', 'builtin = "plane_box"').replace('"none"', '"constant"'))
    a = tmp_path / "a"
    assert _cli(capsys, "run", tune_cfg, "--out", a)[0] == 0
    for args in (["tune", tune_cfg, "--out"], ["perf", "--resolutions", "32", "--scaling", "", "--repeats", "1",
                                              "--no-sweep", "--no-frame", "--out"], ["report", a, a, "--out"]):
        out = tmp_path / args[0]
        h = holder(out)
        rc, err = _cli(capsys, *args, out)
        assert rc == 2, (args, err)
        _one_line(err, str(out), f"process {h.pid}")
        assert sorted(p.name for p in out.iterdir()) == [".dsm-lock"]       # nothing written
        h.kill()
    rc, err = _cli(capsys, "report", a, a, "--out", tmp_path / "report")   # free again after SIGKILL
    assert rc == 0, err
    assert (tmp_path / "report" / "compare.md").is_file()


def test_the_api_takes_the_same_lock(tmp_path, holder):
    out = tmp_path / "o"
    h = holder(out)
    with pytest.raises(ConfigError) as e:
        dsm.run(config.parse(tomllib.loads(tiny_toml())), out=out, report=False)
    assert e.value.key == "out" and f"process {h.pid}" in str(e.value) and str(out) in str(e.value)
    assert sorted(p.name for p in out.iterdir()) == [".dsm-lock"]
    h.kill()
    res = dsm.run(config.parse(tomllib.loads(tiny_toml())), out=out, report=False)
    assert len(res.rows) == 1 and not (out / ".dsm-lock").exists()


def test_the_lock_is_an_os_lock_on_the_file(tmp_path):
    """Held here, a second open of the file cannot flock it; released, the file is gone."""
    import fcntl
    held = lock.acquire(tmp_path / "o")
    assert (tmp_path / "o" / ".dsm-lock").read_text().strip() == str(os.getpid())
    fd = os.open(tmp_path / "o" / ".dsm-lock", os.O_RDWR)
    with pytest.raises(BlockingIOError):
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.close(fd)
    held.release()
    assert not (tmp_path / "o" / ".dsm-lock").exists()
    lock.acquire(tmp_path / "o").release()              # free again


@pytest.mark.slow
def test_a_rerun_after_a_kill_names_resume_and_force(tmp_path, capsys, cfg_file, holder):
    """A run killed with SIGKILL: run.json says running and a stale lock file stays; a plain re-run
    says how to go on (--resume) or start again (--force)."""
    out = tmp_path / "o"
    assert _cli(capsys, "run", cfg_file, "--out", out)[0] == 0
    run = json.loads((out / "run.json").read_text())
    (out / "run.json").write_text(json.dumps(dict(run, state="running")))
    holder(out).kill()
    rc, err = _cli(capsys, "run", cfg_file, "--out", out)
    assert rc == 2
    _one_line(err, str(out), "--resume", "--force")
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, "--resume")
    assert rc == 0 and any("1 finished cases kept" in l for l in err), err
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
