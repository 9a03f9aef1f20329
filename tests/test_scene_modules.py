"""dsm/scenes/load.py split one concept per module: every public name of the old flat module is
defined in the home listed here, and (since 0.2.0, CHANGELOG.md) no longer handed on as
``dsm.scenes.<name>``."""
import importlib
import subprocess
import sys

import pytest
from pathlib import Path

import dsm.scenes

ROOT = Path(__file__).resolve().parent.parent

# the public names of dsm/scenes/load.py before the split (commit 83ef73f), by new home
HOMES = {
    "params": ["BUILTINS", "DoubleTorusParams", "FILE_SUFFIXES", "FileParams", "FloatingPlateParams", "GrazingParams",
               "LShapeParams", "LongGroundParams", "ORIGIN", "PRECISIONS", "Placement", "PlaneBoxParams",
               "PlaneParams", "RoomParams", "StackedPlatesParams", "TerrainParams"],
    "geometry": ["CROSS_MAX", "CROSS_MIN", "box", "catmull_clark", "double_torus", "make_mesh", "normalize",
                 "polycube", "prism", "quad", "rotation"],
    "builtins": ["builtin_geometry", "scale_range"],
    "camera": ["NEAR_MIN", "clip_error", "far_bound", "look_at_sensor", "posed_camera"],
    "checks": ["check_mesh"],
    "spec": ["parse_scene"],
    "ply": ["PLY_ORDER", "PLY_TYPES", "ply_index_problem"],
    "emitters": ["default_light", "describe_light", "emitter_to_light", "lights_of"],
    "data": ["SceneData"],
    "load": ["check", "from_mitsuba"],
}


def test_every_old_name_is_in_its_new_home_only():
    for home, names in HOMES.items():
        module = importlib.import_module(f"dsm.scenes.{home}")
        for name in names:
            value = getattr(module, name)
            if callable(value):           # defined there, not merely imported there
                assert value.__module__ == f"dsm.scenes.{home}", (home, name)
            # the package hands nothing on: a name is read from its module (no __getattr__ alias)
            assert name not in vars(dsm.scenes) and not hasattr(dsm.scenes, "__getattr__"), (home, name)


@pytest.mark.slow
def test_a_module_imported_first_in_a_fresh_process():
    """``from . import exact_frame`` asks the package's __getattr__ first: it must import the
    submodule, not search the old homes while one of them is half imported (a circular import)."""
    for home in ("data", "files", "load", "exact_frame"):
        code = f"import sys; sys.path[:0] = [{str(ROOT)!r}]; from dsm.scenes import {home}; print({home}.__name__)"
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert out.returncode == 0 and out.stdout.strip() == f"dsm.scenes.{home}", out.stderr[-2000:]
