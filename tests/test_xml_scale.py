"""XML scenes in other units (`scale` on an XML [[scene]], dsm.scenes.xml_scale): the Cornell box
(Mitsuba's, in millimetre-like units, 556 across) scaled by 0.001 has its shapes' bounds, camera
position and clip planes times 0.001 against the file loaded as is, and a run of it gives the counts
of the run at scale 1 for every scheme whose bias is in texels or ranges (scale-free), while one
world bias means another thing."""
from pathlib import Path

import numpy as np
import pytest

from conftest import MESHES

CBOX = MESHES / "cbox_mitsuba" / "cbox.xml"


def test_scaled_xml_loads_the_file_s_scene_times_the_scale():
    import mitsuba as mi
    from dsm.scenes import files
    from dsm.core import env
    env.use_variant("llvm_ad_rgb")
    ref = mi.load_file(str(CBOX), optimize=False)
    got = files.load_xml_scene(CBOX, 0.001)
    for a, b in zip(ref.shapes(), got.shapes()):
        np.testing.assert_allclose(np.array(b.bbox().min), np.array(a.bbox().min) * 0.001, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(np.array(b.bbox().max), np.array(a.bbox().max) * 0.001, rtol=1e-6, atol=1e-7)
    m_ref = np.array(ref.sensors()[0].world_transform().matrix, float).reshape(4, 4)
    m_got = np.array(got.sensors()[0].world_transform().matrix, float).reshape(4, 4)
    np.testing.assert_allclose(m_got[:3, :3], m_ref[:3, :3], atol=1e-6)             # the same orientation
    np.testing.assert_allclose(m_got[:3, 3], m_ref[:3, 3] * 0.001, rtol=1e-6)         # the position in metres
    for clip in ("near_clip", "far_clip"):
        assert getattr(got.sensors()[0], clip)() == pytest.approx(getattr(ref.sensors()[0], clip)() * 0.001, rel=1e-6)
    assert str(Path(CBOX).parent) not in [str(p) for p in mi.file_resolver()]      # the resolver restored


def _cfg(scale):
    return {"experiment": {"name": f"cb{scale}"}, "camera": {"resolution": [48, 48]},
            "scene": [{"file": str(CBOX), "scale": scale}],
            "light": [{"type": "spot", "position": [278.0, 500.0, 200.0], "target": [278.0, 0.0, 280.0], "cutoff": 50},
                      {"type": "directional", "direction": [-0.3, -1.0, 0.4]}],
            "map": {"resolution": 96}, "timing": {"repeats": 1},
            "scheme": [{"name": "none"}, {"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"},
                       {"name": "normal_offset"}, {"name": "constant", "bias": 2.0}]}


@pytest.mark.slow
def test_the_cornell_box_in_metres_counts_as_in_its_own_units(tmp_path):
    """The config's light positions scale with the scene; texel and range biases are scale-free, so
    every count is the unscaled run's (no bias: its acne, rounding itself, within 2); the world
    bias of 2 (2 mm or 2 m) is not."""
    import dsm
    a = dsm.run(_cfg(1.0), out=tmp_path / "a", report=False)
    b = dsm.run(_cfg(0.001), out=tmp_path / "b", report=False)
    assert len(a.rows) == len(b.rows) == 10 and b.run["n_failed"] == 0
    for ra, rb in zip(a.rows, b.rows):
        assert ra["n_receivers"] == rb["n_receivers"] > 0
        if ra["params"] == "bias=2":
            assert (ra["n_acne"], ra["n_peterpan"]) != (rb["n_acne"], rb["n_peterpan"])
        elif ra["scheme"] == "none":         # no bias: its acne is the rounding of a depth against itself
            assert abs(ra["n_acne"] - rb["n_acne"]) <= 2 and ra["n_peterpan"] == rb["n_peterpan"]
        else:
            assert (ra["n_acne"], ra["n_peterpan"]) == (rb["n_acne"], rb["n_peterpan"]), (ra["light"], ra["params"])


def test_an_xml_include_refuses_a_scale(tmp_path):
    from dsm.scenes import xml_scale
    (tmp_path / "inner.xml").write_text('<scene version="3.0.0"/>')
    (tmp_path / "outer.xml").write_text('<scene version="3.0.0"><include filename="inner.xml"/></scene>')
    with pytest.raises(ValueError, match="include"):
        xml_scale.scaled_text(tmp_path / "outer.xml", 2.0)


def test_a_broken_xml_with_a_scale_is_one_config_error(tmp_path):
    """Not a traceback: the same one line as the file loaded at scale 1."""
    import shutil
    from dsm.config import read as config
    from dsm import pipeline
    from dsm.core.types import ConfigError
    folder = tmp_path / "cb"
    shutil.copytree(CBOX.parent, folder)
    text = (folder / "cbox.xml").read_text()
    (folder / "broken.xml").write_text(text[:len(text) // 2])
    cfg = config.parse({"experiment": {"name": "b"}, "scene": [{"file": str(folder / "broken.xml"), "scale": 0.01}],
                        "map": {"resolution": 16}, "scheme": [{"name": "none"}]}, "<test>")
    with pytest.raises(ConfigError) as e:
        pipeline.prepare(cfg)
    assert e.value.key == "scene[0].file" and "pars" in str(e.value).lower() and "\n" not in str(e.value)


def test_a_moved_xml_scene_holds_its_shapes_and_camera_at_scale_times_file_plus_translate():
    """``translate`` after ``scale``: every shape's bounds and the camera's position are the file's times
    the scale plus the move (numpy float64), the camera's orientation the file's."""
    import mitsuba as mi
    from dsm.scenes import files
    from dsm.core import env
    env.use_variant("llvm_ad_rgb")
    move = np.array([300.0, -20.0, 7.5])
    ref = mi.load_file(str(CBOX), optimize=False)
    got = files.load_xml_scene(CBOX, 0.01, tuple(move))
    for a, b in zip(ref.shapes(), got.shapes()):
        for end in ("min", "max"):
            want = np.array(getattr(a.bbox(), end), float) * 0.01 + move
            np.testing.assert_allclose(np.array(getattr(b.bbox(), end), float), want, rtol=0, atol=1e-4)
    m_ref = np.array(ref.sensors()[0].world_transform().matrix, float).reshape(4, 4)
    m_got = np.array(got.sensors()[0].world_transform().matrix, float).reshape(4, 4)
    np.testing.assert_allclose(m_got[:3, :3], m_ref[:3, :3], atol=1e-6)
    np.testing.assert_allclose(m_got[:3, 3], m_ref[:3, 3] * 0.01 + move, rtol=0, atol=1e-4)


@pytest.mark.slow
def test_the_cornell_box_far_from_the_origin_keeps_its_exact_side(tmp_path):
    """At 1e4 and 1e5 from the origin (metres) the exact side is traced in a frame centred on the box
    (dsm.scenes.exact_frame): every case's receivers and exact shadowed count are the origin's, while
    the map, held in float32 world coordinates, loses headroom (texel_f32_steps) as the offset grows."""
    import dsm
    rows = {}
    for x in (0.0, 1e4, 1e5):
        cfg = {**_cfg(0.001), "scene": [{"file": str(CBOX), "scale": 0.001, "translate": [x, x / 2, 0.0]}]}
        cfg["light"] = cfg["light"][:1]
        rows[x] = dsm.run(cfg, out=tmp_path / f"at{x:g}", report=False).rows
    for x in (1e4, 1e5):
        for a, b in zip(rows[0.0], rows[x]):
            assert (a["n_receivers"], a["n_gt_shadowed"]) == (b["n_receivers"], b["n_gt_shadowed"]), (x, a["params"])
    steps = [float(np.median([r["texel_f32_steps"] for r in rows[x]])) for x in (0.0, 1e4, 1e5)]
    assert steps[0] > 100 * steps[1] and steps[1] > 4 * steps[2]      # float32 steps: 2^3 coarser at 1e5 than 1e4
