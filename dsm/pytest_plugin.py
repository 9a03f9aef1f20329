"""dsm's pytest plugin (registered by the entry point ``pytest11``, so a test file imports nothing):

- ``dsm_results``: a session fixture, a function ``config -> Results`` that runs each experiment
  (a TOML path, a dict or a Config) once per test session, keyed by the config's text (a path's
  by its file's bytes) and the variant, into the session's temporary folder;
- the marker ``dsm_slow`` for experiment tests a quick run deselects (``-m "not dsm_slow"``).

Loading it imports nothing of Mitsuba or Dr.Jit (the fixture does, when a test first asks).
"""
from __future__ import annotations

import hashlib
import json
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


@pytest.fixture(scope="session")
def dsm_results(tmp_path_factory):
    """A function (config, variant=None) -> Results: each config run once per test session."""
    runs = {}

    def run(config, variant: str | None = None):
        """The Results of ``config``, run on first use in this session."""
        key = (config_key(config), variant)
        if key not in runs:
            import dsm
            runs[key] = dsm.run(config, out=tmp_path_factory.mktemp("dsm") / "run", variant=variant)
        return runs[key]
    run.runs = runs
    return run
