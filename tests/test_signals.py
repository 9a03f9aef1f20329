"""Signals (dsm/core/signals.py): SIGTERM leaves a run interrupted, not running; Ctrl-C while a command
starts is one line."""
import subprocess
import sys

import pytest




# SIGTERM sent from inside metrics.csv's second row write: between the row and its record's entry,
# the point where the sink's three writes once raced (issue 76); no sleep, no timer
SIGTERM_MID_ROW = """
import os, signal, sys
from dsm import cli
from dsm.report import io
write, done = io.CsvWriter.write, []
def write_then_term(self, row):
    write(self, row)
    done.append(row)
    if len(done) == 2:
        os.kill(os.getpid(), signal.SIGTERM)
io.CsvWriter.write = write_then_term
sys.argv = ["dsm", *sys.argv[1:]]
sys.exit(cli.main())
"""


@pytest.mark.slow
def test_sigterm_leaves_the_run_interrupted_not_running(tmp_path):
    import json as jsonmod
    cfg = tmp_path / "slow.toml"
    cfg.write_text('[experiment]\nname = "slow"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   '[map]\nresolution = [32, 48]\n[[scheme]]\nname = "constant"\n'
                   f'bias = {[0.001 * k for k in range(1, 6)]}\n')
    out = tmp_path / "o"
    p = subprocess.run([sys.executable, "-c", SIGTERM_MID_ROW, "run", str(cfg), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 130, p.stderr[-500:]
    run = jsonmod.loads((out / "run.json").read_text())
    assert run["state"] == "interrupted"
    assert "interrupted" in p.stderr and "--resume" in p.stderr
    # the row whose write the signal came in was recorded with it: run.json and metrics.csv agree
    rows = (out / "metrics.csv").read_text().count("\n") - 1
    assert run["n_cases_ok"] == rows == 2
    # and --resume neither loses nor repeats a case
    again = subprocess.run([sys.executable, "-m", "dsm.cli", "run", str(cfg), "--out", str(out), "--resume"],
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-500:]
    cases = [line.split(",")[0] for line in (out / "metrics.csv").read_text().splitlines()[1:]]
    assert len(cases) == len(set(cases)) == jsonmod.loads((out / "run.json").read_text())["n_cases_ok"] == 10


def test_ctrl_c_while_the_command_starts_is_one_line(monkeypatch, capsys):
    """The dsm command's entry point (dsm.launch): a Ctrl-C while the command line's modules import
    ends it with one line and exit 130, not a traceback."""
    import builtins
    import sys
    from dsm import launch
    real = builtins.__import__

    def interrupted(name, globals=None, locals=None, fromlist=(), level=0):
        if (level == 1 and name == "cli") or name == "dsm.cli":
            raise KeyboardInterrupt
        return real(name, globals, locals, fromlist, level)
    monkeypatch.delitem(sys.modules, "dsm.cli", raising=False)
    monkeypatch.setattr(builtins, "__import__", interrupted)
    assert launch.main() == 130
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err == ["dsm: interrupted (while starting)"]
