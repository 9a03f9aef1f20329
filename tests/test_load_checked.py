"""dsm/scenes/load.py's hand-on from check to a run: the first scene check loaded is the run's first load
(taken once, only for the same scene, camera and resolution), the same geometry and camera as a load of its own."""
import numpy as np

from conftest import base_config
from dsm import pipeline
from dsm.config import read as config
from dsm.scenes import load as scenes


def _vertices(sd) -> list:
    return [np.asarray(s.vertex_positions_buffer()) for s in sd.scene.shapes()]


def test_check_hands_its_first_scene_on_once_and_only_for_the_same_load():
    """prepare's check hands plane_box on: taken once for its own spec, camera and size, equal to a load of its own."""
    cfg = config.parse(base_config(scene=[{"builtin": "plane_box"}, {"builtin": "plane"}],
                                   camera={"resolution": [24, 16]}), "<test>")
    pipeline.prepare(cfg)                              # the variant, then check: the first scene handed on
    handed = scenes.HANDED[0][1]
    first, second = cfg.scenes
    assert scenes.load_checked(second, cfg.camera_resolution, cfg.camera) is not handed      # another scene: loaded
    assert scenes.load_checked(first, (16, 16), cfg.camera) is not handed                    # another camera size
    got = scenes.load_checked(first, cfg.camera_resolution, cfg.camera)
    assert got is handed and scenes.HANDED == []                                              # taken, once
    fresh = scenes.load(first, cfg.camera_resolution, cfg.camera)
    again = scenes.load_checked(first, cfg.camera_resolution, cfg.camera)
    assert again is not got                                                                   # a second take loads
    assert got.shape_names == fresh.shape_names == ["ground", "box"]
    assert all(np.array_equal(a, b) for a, b in zip(_vertices(got), _vertices(fresh)))
    assert all(np.array_equal(a, b) for a, b in zip(got.bbox, fresh.bbox))
    assert all(np.array_equal(a, b) for a, b in zip(got.camera_pose, fresh.camera_pose))


def test_a_failed_check_hands_nothing_on(tmp_path):
    """A check that refuses a scene (a mesh file that does not load) hands none on, not even its good first one."""
    import pytest
    (tmp_path / "bad.ply").write_text("not a ply file\n")
    good = config.parse(base_config(scene=[{"builtin": "plane"}]), "<test>")
    pipeline.prepare(good)
    assert len(scenes.HANDED) == 1
    bad = config.parse(base_config(scene=[{"builtin": "plane"}, {"file": str(tmp_path / "bad.ply")}]), "<test>")
    with pytest.raises(config.ConfigError):
        scenes.check(bad)
    assert scenes.HANDED == []


def test_a_run_takes_the_scene_its_check_handed_on(run_dict):
    """dsm.run's first scene load is the check's (nothing left handed on after the run)."""
    run_dict(base_config(camera={"resolution": [16, 16]}, map={"resolution": 16}))
    assert scenes.HANDED == []
