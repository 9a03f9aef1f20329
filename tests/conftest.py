import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT.parent / "shared" / "meshes"


@pytest.fixture(scope="session", autouse=True)
def variant():
    """One variant for the session (llvm_ad_rgb unless DSM_VARIANT says otherwise)."""
    from dsm import env
    v = env.use_variant(os.environ.get("DSM_VARIANT"))
    yield v
    import drjit as dr
    dr.sync_thread()
    dr.flush_kernel_cache()
    dr.flush_malloc_cache()


def base_config(**over):
    """A small experiment as a dict; keyword tables replace the defaults."""
    cfg = {"experiment": {"name": "test"}, "camera": {"resolution": [192, 192]},
           "scene": [{"builtin": "plane"}], "map": {"resolution": 128},
           "scheme": [{"name": "none"}], "timing": {"repeats": 1}}
    cfg.update(over)
    return cfg


@pytest.fixture
def run_dict(tmp_path):
    import dsm

    def _run(cfg, name="out"):
        return dsm.run(cfg, out=tmp_path / name)
    return _run
