"""dsm bench's arithmetic and its frozen frame (times are measured, never asserted)."""
import math

import numpy as np


def test_fitted_exponent_recovers_a_power_law():
    from dsm.tools.bench import fitted_exponent
    texels = np.array([1024, 2048, 4096, 8192], float) ** 2
    assert math.isclose(fitted_exponent(texels, 3e-6 * texels), 1.0, rel_tol=1e-9)
    assert math.isclose(fitted_exponent(texels, 0.5 * texels ** 0.75), 0.75, rel_tol=1e-9)
    assert math.isnan(fitted_exponent(texels[:1], [1.0]))


def test_kernel_ms_counts_the_kernels_of_one_call():
    import drjit as dr
    import mitsuba as mi
    from dsm.tools import timing
    timing.enable_history()
    x = dr.arange(mi.Float, 100_000)
    dr.eval(x)
    # one fused expression is one kernel; evaluating its input first makes two
    assert timing.kernel_ms(lambda: (dr.sin(x) * 2 + 1,), 2)[1] == 1

    def two():
        y = dr.sin(x) * 2
        dr.eval(y)
        return (y + 1,)
    assert timing.kernel_ms(two, 2)[1] == 2


def test_the_frozen_frame_replays_the_traced_frame():
    """The frame (map and every single-layer lookup) recorded by dr.freeze and replayed gives the
    traced frame's bits: every Dr.Jit value it reads is one of its inputs."""
    from dsm.tools import bench, timing
    from dsm.config.read import LightSpec, SceneSpec
    from dsm.scenes.params import PlaneBoxParams
    timing.enable_history()
    spec = SceneSpec(builtin="plane_box", params=PlaneBoxParams(), label="plane_box")
    row = bench.frame_cost(spec, LightSpec("directional", direction=(-0.4, -0.3, -1.0)), R=64, camera=64, repeats=1)
    assert row.get("frozen_error") is None, row.get("frozen_error")
    assert row["frozen_same"] is True
    assert row["receivers"] > 0 and len(row["schemes"]) == len(bench.FRAME_SCHEMES)
