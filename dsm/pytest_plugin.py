"""dsm's pytest plugin (registered by the entry point ``pytest11``, so a test file imports nothing):

- ``dsm_results``: a session fixture, a function ``config -> Results`` that runs each experiment
  (a TOML path, a dict or a Config) once per test session, without its report (``report=True`` draws it), keyed by the config's text (a path's
  by its file's bytes) and the variant, into the session's temporary folder. Under pytest-xdist
  (``pytest -n N``) the workers share it: the first worker to ask for a config runs it, holding a
  lock on a file in the folder the workers' temporary folders sit in, and the others wait for it
  and read its Results (pickled) instead of running the config again;
- the marker ``dsm_slow`` for experiment tests a quick run deselects (``-m "not dsm_slow"``).

Loading it imports nothing of Mitsuba or Dr.Jit (the fixture does, when a test first asks).
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import pickle
from pathlib import Path

import pytest


def pytest_configure(config):
    """Register the marker."""
    config.addinivalue_line("markers", "dsm_slow: a dsm experiment test that takes minutes (deselect with "
                            "-m 'not dsm_slow')")


def config_key(config) -> str:
    """What identifies a run of ``config``: a TOML file's path and bytes, or a dict's JSON text."""
    if isinstance(config, (str, Path)):
        path = Path(config).resolve()
        try:
            return f"{path}:{hashlib.sha256(path.read_bytes()).hexdigest()}"
        except OSError:             # missing or unreadable: dsm.run says why in its ConfigError
            return f"{path}:unreadable"
    if isinstance(config, dict):
        return json.dumps(config, sort_keys=True, default=str)
    return repr(config)


def shared_folder(tmp_path_factory) -> Path | None:
    """The folder this session's xdist workers share (under their temporary folders' common parent), or
    None outside xdist, where one process runs every test and there is no one to share with."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return None
    # xdist gives worker gwN the basetemp <this run's root>/popen-gwN: the root is this run's alone
    folder = tmp_path_factory.getbasetemp().parent / "dsm-results"
    folder.mkdir(exist_ok=True)
    return folder


def run_once_shared(folder: Path, key, make):
    """``make()``'s Results, made by the first worker that asks for ``key`` and read by the others.

    The first holds an exclusive ``flock`` on ``<key>.lock`` while it runs, so a second worker asking
    for the same key blocks until the Results are written, then reads them. A run that raises writes
    nothing: the next worker runs it again and gets its own error, as it would alone."""
    name = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
    done = folder / f"{name}.pickle"
    with open(folder / f"{name}.lock", "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)    # released when the file closes, also if this worker dies
        if done.exists():
            return pickle.loads(done.read_bytes())
        results = make()
        try:
            data = pickle.dumps(results)
        except (pickle.PicklingError, TypeError, AttributeError):
            return results                  # Results that cannot be pickled: each worker runs its own
        part = folder / f"{name}.part"
        part.write_bytes(data)
        part.replace(done)                  # whole or absent: a reader never sees half a pickle
        return results


@pytest.fixture(scope="session")
def dsm_results(tmp_path_factory):
    """A function (config, variant=None, report=False) -> Results: each config run once per test session (and
    once across the workers of ``pytest -n N``), without its report unless asked (a threshold reads numbers)."""
    runs = {}
    shared = shared_folder(tmp_path_factory)

    def run(config, variant: str | None = None, report: bool = False):
        """The Results of ``config``, run on first use in this session; ``report``: draw its figures and
        report.html too (dsm.run(report=...): half of a small run's time, which a threshold does not read)."""
        key = (config_key(config), variant, report)
        if key not in runs:
            import dsm
            make = lambda: dsm.run(config, out=tmp_path_factory.mktemp("dsm") / "run", variant=variant, report=report)
            runs[key] = make() if shared is None else run_once_shared(shared, key, make)
        return runs[key]
    run.runs = runs
    return run
