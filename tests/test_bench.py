"""dsm perf's arithmetic and its frozen frame (times are measured, never asserted)."""
import math

import time

import numpy as np


def test_fitted_exponent_recovers_a_power_law():
    from dsm.perf.bench import fitted_exponent
    texels = np.array([1024, 2048, 4096, 8192], float) ** 2
    assert math.isclose(fitted_exponent(texels, 3e-6 * texels), 1.0, rel_tol=1e-9)
    assert math.isclose(fitted_exponent(texels, 0.5 * texels ** 0.75), 0.75, rel_tol=1e-9)
    assert math.isnan(fitted_exponent(texels[:1], [1.0]))


def test_kernel_ms_counts_the_kernels_of_one_call():
    import drjit as dr
    import mitsuba as mi
    from dsm.core import timing
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
    from dsm.perf import bench
    from dsm.core import timing
    from dsm.config.read import LightSpec, SceneSpec
    from dsm.scenes.params import PlaneBoxParams
    timing.enable_history()
    spec = SceneSpec(builtin="plane_box", params=PlaneBoxParams(), label="plane_box")
    row = bench.frame_cost(spec, LightSpec("directional", direction=(-0.4, -0.3, -1.0)), R=64, camera=64, repeats=1)
    assert row.get("frozen_error") is None, row.get("frozen_error")
    assert row["frozen_same"] is True
    assert row["receivers"] > 0 and len(row["schemes"]) == len(bench.FRAME_SCHEMES)


def test_the_resampled_terrain_at_the_dem_s_own_size_is_the_terrain():
    """Resampled to the DEM's own 344 x 403 grid (275,772 triangles), the bench's terrain is the
    scene's terrain vertex for vertex and face for face (the bilinear weights are 0 or 1)."""
    from dsm.scenes import terrain
    from dsm.perf import bench_geometry
    verts, faces = terrain.mesh(1)
    v, f = bench_geometry.resampled_terrain(len(faces))
    np.testing.assert_array_equal(v, verts)
    np.testing.assert_array_equal(f, faces)


def test_the_resampled_terrain_interpolates_bilinearly_and_writes_its_triangles(tmp_path):
    """Between DEM samples the height is the bilinear blend, computed here in numpy from the
    DEM's grid; the PLY written holds the triangles asked for (read back from its header)."""
    from dsm.scenes import terrain
    from dsm.scenes.size import ply_triangles
    from dsm.perf import bench_geometry
    verts, _ = terrain.mesh(1)
    z0 = verts[:, 2].reshape(344, 403)
    v, f = bench_geometry.resampled_terrain(1_000_000)
    rows, cols = bench_geometry.grid_for(1_000_000, 402 / 343)
    assert 2 * (rows - 1) * (cols - 1) == len(f) and abs(len(f) - 1_000_000) < 0.01 * 1_000_000
    fr, fc = np.linspace(0, 343, rows)[123], np.linspace(0, 402, cols)[456]
    r, c = int(fr), int(fc)
    wr, wc = fr - r, fc - c
    z = (1 - wr) * ((1 - wc) * z0[r, c] + wc * z0[r, c + 1]) + wr * ((1 - wc) * z0[r + 1, c] + wc * z0[r + 1, c + 1])
    assert np.isclose(v[123 * cols + 456, 2], z, rtol=0, atol=1e-9)
    assert bench_geometry.write_ply(tmp_path / "t.ply", v[:9], np.array([[0, 1, 2], [3, 4, 5]])) == 2
    assert ply_triangles(tmp_path / "t.ply") == 2


def test_kernel_launches_are_counted_apart_inside_and_outside_the_timed_repeats():
    """One evaluated output is one kernel a call: a measure with 3 repeats is 1 launch outside
    (the cold call) and 3 inside; kernels launched between measures count outside."""
    import drjit as dr
    import mitsuba as mi
    from dsm.core import env, timing
    env.use_variant("llvm_ad_rgb")
    timing.enable_history()
    timing.reset_launches()
    x = dr.arange(mi.Float, 1000)
    scale = dr.opaque(mi.Float, 2.0)
    timing.measure(lambda: (x * scale + 1.0,), repeats=3)
    assert timing.LAUNCHES == {"outside_repeats": 1, "timed_repeats": 3}
    dr.eval(x * scale - 1.0)
    dr.eval(x * scale - 2.0)
    assert timing.drain_launches() == 2 and timing.LAUNCHES["outside_repeats"] == 3


def test_measure_kernel_times_every_call_and_leaves_no_cold_call_outside():
    """measure_kernel with 3 repeats: 3 launches, all timed, none outside (the old measure: one cold
    call outside and 3 timed); its output the last call's; the first call's kernel count and cold wall
    apart; a kernel's execution time (the median) below the first call's wall clock, which adds its
    tracing and compilation to its own kernel."""
    import drjit as dr
    import mitsuba as mi
    from dsm.core import env, timing
    env.use_variant("llvm_ad_rgb")
    timing.enable_history()
    timing.reset_launches()
    x = dr.arange(mi.Float, 100_000)
    scale = dr.opaque(mi.Float, 3.0)
    # a literal no earlier process used: the first call compiles (Dr.Jit's kernel cache on disk
    # outlives a process; a cached kernel's first call is a warm one, as fast as the repeats)
    offset = float(np.float32(1.0 + (time.time_ns() % 1_000_003) / 1_000_003))
    (y,), t = timing.measure_kernel(lambda: (x * scale + offset,), repeats=3)
    assert timing.LAUNCHES == {"outside_repeats": 0, "timed_repeats": 3}
    assert t.kernels == 1 and t.cache_misses == 1 and 0 < t.ms < t.cold_ms
    np.testing.assert_array_equal(y.numpy(), np.arange(100_000, dtype=np.float32) * np.float32(3.0) + np.float32(offset))
    timing.measure_kernel(lambda: (x * scale - 1.0,), repeats=1)      # one call: it is the timed one
    assert timing.LAUNCHES == {"outside_repeats": 0, "timed_repeats": 4}


def test_measure_kernel_reports_the_warm_calls_median(monkeypatch):
    """The first call's kernel time (memory touched for the first time) stays out of the median
    when there are later calls, and is the time when it is the only call."""
    from dsm.core import timing
    times = iter([[], [100.0], [1.0], [3.0], [], [7.0]])      # each call drains the history first
    monkeypatch.setattr(timing, "_run", lambda fn: ((), 0.0))
    monkeypatch.setattr(timing, "_jit_kernels", lambda: [{"execution_time": t} for t in next(times)])
    monkeypatch.setattr(timing, "_compiled", lambda hist: (0.0, 0))
    assert timing.measure_kernel(lambda: (), repeats=3)[1].ms == 2.0       # median of 1 and 3, not of 100, 1, 3
    assert timing.measure_kernel(lambda: (), repeats=1)[1].ms == 7.0


def test_measure_calls_makes_repeats_calls_and_reports_the_later_calls_median(monkeypatch):
    """measure_calls (a moment map's clock): ``repeats`` calls in all, as a map build's, not a cold
    call and ``repeats`` more; the first call's wall clock is cold_ms and stays out of the median
    when there are later calls, and is the time when it is the only call."""
    from dsm.core import timing
    walls, calls = iter([100.0, 1.0, 3.0, 50.0, 9.0]), []

    def run(fn):
        calls.append(fn())
        return (len(calls),), next(walls)
    monkeypatch.setattr(timing, "_run", run)
    monkeypatch.setattr(timing, "_jit_kernels", lambda: [])
    out, t = timing.measure_calls(lambda: "called", repeats=3)
    assert len(calls) == 3 and out == (3,) and t.ms == 2.0 and t.cold_ms == 100.0
    assert timing.measure_calls(lambda: "called", repeats=1)[1].ms == 50.0 and len(calls) == 4


def test_the_benchmark_times_each_case_over_its_timing_calls():
    """Every config of a suite case (depth, pre-filtered, flicker) asks for the benchmark's TIMING_CALLS."""
    from dsm.benchmark import suite as suite_mod
    s = suite_mod.load_suite(suite_mod.SUITE_FILE)
    for case in suite_mod.cases(s, "test"):
        for cfg in (case.config, case.prefiltered, case.motion, case.prefiltered_motion):
            if cfg is not None:
                assert cfg["timing"] == {"repeats": suite_mod.TIMING_CALLS}


def test_bench_md_names_the_versions_and_machine_its_times_depend_on():
    import platform

    import drjit as dr
    import mitsuba as mi

    from dsm.core import env
    from dsm.perf.bench import markdown

    doc = {"variant": "llvm_ad_rgb", "threads": 2, "repeats": 1, "builds": [], "lookups": [], "scaling": [],
           "versions": env.versions(), "machine": env.machine()}
    text = markdown(doc)
    assert f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}" in text
    assert f"Python {platform.python_version()}" in text
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), None)
    if cpu:
        assert cpu in text
