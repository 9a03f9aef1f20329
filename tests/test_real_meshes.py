"""Real meshes (../shared/meshes): every mesh classified, nothing NaN, one config for all scales."""
import dataclasses

import pytest

from conftest import MESHES, ROOT, assert_nan_only_where_undefined

pytestmark = pytest.mark.skipif(not MESHES.exists(), reason=f"{MESHES} is absent (real test meshes)")


def test_real_meshes_need_no_per_scene_epsilon(tmp_path):
    import dsm
    from dsm import config
    cfg = config.load(ROOT / "experiments" / "real_meshes.toml")
    cfg = dataclasses.replace(cfg, camera_resolution=(128, 128), timing_repeats=1,
                              map=dataclasses.replace(cfg.map, resolution=(512,)))
    res = dsm.run(cfg, out=tmp_path / "real")
    assert res.run["n_failed"] == 0 and res.run["n_skipped"] == 0
    scenes = {r["scene"] for r in res.rows}
    assert len(scenes) == 7
    for r in res.rows:
        assert_nan_only_where_undefined(r)
    for s in scenes:
        rs = res.where(scene=s)
        assert rs.n_receivers.min() > 2000 and rs.n_gt_lit.min() > 1000 and rs.n_gt_shadowed.min() > 20, s
        # the same texel-relative schemes work from a 0.15-unit bunny to a 556 mm Cornell box
        assert rs.where(scheme="adaptive").acne_rate.max() < 0.03, s
        assert rs.where(scheme="midpoint", params="culling=back_closed").acne_rate.max() < 0.01, s
    cbox = res.where(scene="cbox").rows[0]
    assert cbox["light"] == "0:point" and cbox["view"] == "cube"     # the default light at its luminaire
    # each mesh was loaded once for all its cases (one G-buffer per scene)
    assert set(res.run["gbuffer_ms"]) == scenes
