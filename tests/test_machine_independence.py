"""Results that do not depend on how rays are packed (docs/design.md, *Results that do not depend
on the machine*): the tile a texel was cast in, the packet a pixel travelled in, the CPU's
vector width. Expected values: the same build done another way (a single pass, another order,
another width)."""
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, base_config

BUILDS = [(set(), None), ({"slope"}, None), ({"z2", "slope"}, None), ({"z2"}, "back"), ({"z2"}, "front"),
          ({"z2", "slope"}, "back_closed")]


def _room_cube(res=48):
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    from dsm.pipeline import make_view
    from dsm.core.types import LightSpec
    sd = scenes.load(config.parse(base_config(scene=[{"builtin": "room"}]), "<test>").scenes[0], (16, 16))
    view = make_view(LightSpec("point", position=(0.2, 0.1, 1.8), direction=(0, 0, -1.0)), res, None, sd.bbox, "cube")
    return sd, view


@pytest.mark.slow
@pytest.mark.parametrize("needs,culling", BUILDS)
def test_tiles_of_any_size_give_the_single_pass_bits(variant, needs, culling):
    """Tiles of 1000, 4097 and 5000 texels leave partial packets at every vector width."""
    from dsm.maps import shadowmap
    sd, view = _room_cube()
    modes = shadowmap.cull_modes_for(culling, [True] * len(sd.shape_names)) if culling else None
    one = shadowmap.build(sd.scene, view, needs, culling or "none", modes)
    for tile in (1000, 4097, 5000):
        tiled = shadowmap.build(sd.scene, view, needs, culling or "none", modes, tile=tile)
        assert one.tiles == 1 and tiled.tiles == -(-view.n_texels // tile)
        for a, b in zip(shadowmap.arrays(one), shadowmap.arrays(tiled)):
            np.testing.assert_array_equal(a.numpy(), b.numpy(), err_msg=f"tile {tile}")
        assert one.rays == tiled.rays


def test_a_pixels_hit_does_not_depend_on_its_packet(variant):
    """The G-buffer's rays cast in another order and offset (every packet holds other pixels)
    hit the same points of the same shapes."""
    import drjit as dr
    import mitsuba as mi
    from dsm.config import read as config
    from dsm.scenes import gbuffer, load as scenes
    sd = scenes.load(config.parse(base_config(scene=[{"builtin": "room"}]), "<test>").scenes[0], (96, 96))
    full = gbuffer.cast(sd.scene, sd.sensor, 96, 96)
    order = np.r_[np.arange(96 * 96 - 1, 4000, -1), np.arange(3, 4001)].astype(np.uint32)   # reversed, shifted
    _, pi, si = gbuffer.primary_hits(sd.scene, sd.sensor, 96, 96, mi.UInt32(order))
    dr.eval(pi, si)
    np.testing.assert_array_equal(si.p.numpy(), full.p.numpy()[:, order])
    np.testing.assert_array_equal(pi.prim_index.numpy()[full.hit[order]],
                                  full.si.prim_index.numpy()[order][full.hit[order]])


def _cpu_flags() -> set:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


@pytest.mark.slow
@pytest.mark.skipif(not {"avx2", "fma"} <= _cpu_flags(), reason="forcing Dr.Jit's vector width needs an AVX2 CPU")
def test_maps_and_gbuffer_are_the_same_bits_at_every_vector_width(variant, tmp_path):
    """The room's cube maps (first layer, slope, second layer, culled) and its G-buffer, built in
    processes whose Dr.Jit LLVM vector width is forced to 4, 8 and 16 lanes, are the bits of the
    build in this process (the CPU's own width)."""
    import helpers_width_probe
    here = helpers_width_probe.arrays()
    for width in (4, 8, 16):
        out = tmp_path / f"w{width}.npz"
        p = subprocess.run([sys.executable, str(ROOT / "tests" / "helpers_width_probe.py"), str(width), str(out)],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        got = np.load(out)
        assert int(got["width"]) == width
        for k, v in here.items():
            np.testing.assert_array_equal(got[k], v, err_msg=f"{k} at width {width}")
