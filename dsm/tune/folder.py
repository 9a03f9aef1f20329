"""The folder ``dsm tune`` writes into: what it may hold, what --force replaces, what --resume needs.

The command line (dsm.cli) and the Python API (dsm.tune.tuner.tune) apply the same rules, after
claiming the folder's lock (dsm.experiment.lock.claim).
"""
from __future__ import annotations

from pathlib import Path

from ..experiment.lock import entries, unwritable
from . import blackbox, resume as tune_resume

TUNE_FILES = ("tuned.toml", "table.md", "steps.csv", "tune.json", "plots/tune_loss.png", "bias_map.npy",
              "texel_offsets.npy", "tune_state.json", "optuna.journal")   # what dsm tune writes


def tune_folder(out: Path, name: str, force: bool = False, resume: bool = False) -> tuple:
    """(why dsm tune cannot write into the claimed folder ``out`` or None, whether it resumes the tune
    there); a previous tune that ``force`` replaces has its files removed (only those)."""
    held = entries(out)
    if resume and held:
        return tune_resume.state_problem(out, name) or blackbox.journal_problem(out) or unwritable(out), True
    if held:
        if not force:
            return (f"--out {out}: is not an empty folder; choose another --out, or pass --resume (goes on with a dsm "
                    "tune there, keeping its finished schemes) or --force (replaces a previous dsm tune there)"), False
        if not ((out / "tune.json").is_file() or (out / "tune_state.json").is_file()):     # a stopped tune: its state
            return (f"--out {out}: --force replaces a previous dsm tune (a folder with its tune.json or "
                    "tune_state.json); this one holds neither"), False
        for f in TUNE_FILES:        # its files only: a user's own files beside them stay
            if (out / f).is_file():
                (out / f).unlink()
    return unwritable(out), False       # before the tuning, not when its results are written
