"""Every experiment in experiments/ and the built-in default runs at tiny resolution (no skip list)."""
import dataclasses

import pytest

import dsm
from conftest import MESHES, ROOT
from dsm import config
from dsm.cli import DEFAULT_CONFIG

FILES = sorted((ROOT / "experiments").glob("*.toml")) + [DEFAULT_CONFIG]


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_experiment_runs_tiny(path, tmp_path):
    cfg = config.load(path)          # absent optional meshes are skipped by the run, never here
    tiny = dataclasses.replace(cfg, camera_resolution=(48, 48), timing_repeats=1,
                               map=dataclasses.replace(cfg.map, resolution=(32,),
                                                       texels=(6 * 32 ** 2,) if cfg.map.texels else ()))
    res = dsm.run(tiny, out=tmp_path / "out")
    assert res.run["n_failed"] == 0, res.run["status"]
    present = [s for s in cfg.scenes if not s.missing]
    assert res.run["n_skipped"] == len(cfg.scenes) - len(present)
    if present:
        assert len(res.rows) >= len(cfg.schemes)
    else:                              # every scene is an absent optional mesh: said, not silent
        assert not MESHES.exists() and all("absent" in s["error"] for s in res.run["status"])
    assert (tmp_path / "out" / "table.md").is_file()
