"""Clocks around Dr.Jit work: warm medians, with JIT compile time reported apart.

Each measured function returns the arrays it computes; they are evaluated and the thread
synchronized (``dr.sync_thread()``) before every clock read. The first call is cold and its
compile time is read from Dr.Jit's kernel history (code generation + backend); the reported
time is the median of ``repeats`` warm calls after it.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import drjit as dr


@dataclass
class Timing:
    """One measured function's cost: warm median, JIT compile time, cold run (ms), kernels and cache misses."""
    ms: float            # median of warm runs
    compile_ms: float    # JIT code generation + LLVM backend in the cold run
    cold_ms: float       # the first run, compile included
    kernels: int         # kernels launched by one cold run
    cache_misses: int    # of those, how many were compiled (not found in Dr.Jit's caches)


def enable_history():
    """Turn on Dr.Jit's kernel history (where compile times are read)."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)


def _run(fn):
    dr.sync_thread()
    t0 = time.perf_counter()
    out = fn()
    dr.eval(*[x for x in out if dr.is_array_v(x) or hasattr(type(x), "DRJIT_STRUCT")])
    dr.sync_thread()
    return out, (time.perf_counter() - t0) * 1e3


# JIT kernels this process launched while the history was on: inside a measured function's timed
# (warm) repeats, and everywhere else (cold runs, metrics, images: what batching would save)
LAUNCHES = {"outside_repeats": 0, "timed_repeats": 0}


def _jit_kernels() -> list:
    """The JIT kernels launched since the history was last read (reading it clears it)."""
    return [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]


def drain_launches() -> int:
    """Count the kernels launched since the history was last read as outside timed repeats."""
    n = len(_jit_kernels())
    LAUNCHES["outside_repeats"] += n
    return n


def reset_launches():
    """Start counting launches afresh (what came before is read and dropped)."""
    _jit_kernels()
    LAUNCHES.update(outside_repeats=0, timed_repeats=0)


def _compiled(hist) -> tuple:
    """(code generation + backend ms, kernels not found in Dr.Jit's caches) of a call's kernel history."""
    return (sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in hist),
            sum(1 for k in hist if not k.get("cache_hit", False)))


def measure(fn, repeats: int = 3):
    """Call ``fn`` (returning a tuple of arrays) cold once and warm ``repeats`` times."""
    drain_launches()
    out, cold = _run(fn)
    hist = _jit_kernels()
    LAUNCHES["outside_repeats"] += len(hist)
    compile_ms, misses = _compiled(hist)
    warm = []
    for _ in range(repeats):
        out, ms = _run(fn)
        warm.append(ms)
    LAUNCHES["timed_repeats"] += len(_jit_kernels())
    return out, Timing(statistics.median(warm) if warm else cold, compile_ms, cold, len(hist), misses)


def measure_kernel(fn, repeats: int = 3):
    """Call ``fn`` (returning a tuple of arrays) ``repeats`` times (at least once), every call a timed
    repeat: the reported ms is the summed execution time of the kernels a call launched (Dr.Jit's
    kernel history: the device's own time, without compilation, Python's tracing or launch
    overhead), the median over the calls after the first (the first alone when ``repeats`` is 1:
    its kernels run on memory touched for the first time, 1.2x a warm call's at the median, 3x at
    the 90th percentile on the default experiment). The first call compiles: its code generation
    and backend time is ``compile_ms`` and its wall clock ``cold_ms``. No untimed cold call: the
    outputs are the last call's, and every call's launches are timed repeats."""
    drain_launches()
    kernel, cold, compile_ms, n_kernels, misses, out = [], 0.0, 0.0, 0, 0, None
    for i in range(max(1, repeats)):
        out, ms = _run(fn)
        hist = _jit_kernels()
        LAUNCHES["timed_repeats"] += len(hist)
        kernel.append(sum(k.get("execution_time", 0.0) for k in hist))
        if i == 0:
            cold, n_kernels = ms, len(hist)
            compile_ms, misses = _compiled(hist)
    return out, Timing(statistics.median(kernel[1:] or kernel), compile_ms, cold, n_kernels, misses)


def measure_calls(fn, repeats: int = 3):
    """Wall-clock twin of :func:`measure_kernel` for work that is not all Dr.Jit kernels (a moment
    map's numpy blur): ``fn`` called ``repeats`` times (at least once), the reported ms the median
    of the calls after the first (the first alone when ``repeats`` is 1); the first call's code
    generation and backend time is ``compile_ms`` and its wall clock ``cold_ms``. The same calls as
    a map build's, so a build and its moment map are timed alike, and no call beyond them."""
    drain_launches()
    walls, out, hist = [], None, []
    for i in range(max(1, repeats)):
        out, ms = _run(fn)
        walls.append(ms)
        if i == 0:
            hist = _jit_kernels()
            LAUNCHES["outside_repeats"] += len(hist)
    LAUNCHES["timed_repeats"] += len(_jit_kernels())
    compile_ms, misses = _compiled(hist)
    return out, Timing(statistics.median(walls[1:] or walls), compile_ms, walls[0], len(hist), misses)


def kernel_ms(fn, repeats: int = 3):
    """(median over warm calls of the summed execution time of the kernels one call of ``fn``
    launches, ms; kernels per call): the device's own time, without Python's tracing or launch
    overhead. Turns the kernel history on (:func:`enable_history`)."""
    enable_history()
    _run(fn)                                              # cold: compiled here, not counted
    sums, kernels = [], 0
    for _ in range(max(1, repeats)):
        dr.kernel_history_clear()
        _run(fn)
        hist = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
        sums.append(sum(k.get("execution_time", 0.0) for k in hist))
        kernels = len(hist)
    dr.kernel_history_clear()
    return statistics.median(sums), kernels


def _backend():
    import mitsuba as mi
    return dr.JitBackend.CUDA if mi.variant().startswith("cuda") else dr.JitBackend.LLVM


def reset_peak():
    """Start a new allocation watermark (cached blocks are released first)."""
    dr.sync_thread()
    dr.flush_malloc_cache()
    dr.detail.malloc_clear_statistics()


def peak_bytes() -> int:
    """Dr.Jit's allocation watermark since ``reset_peak`` (the device's memory on CUDA, host on LLVM)."""
    dr.sync_thread()
    return int(dr.detail.malloc_watermark(_backend()))


def kernel_ms_interleaved(fns: dict, repeats: int = 3) -> dict:
    """{name: median over ``repeats`` rounds of one call's summed kernel execution time, ms} for
    each function of ``fns``, called in turn within every round (after one cold call each), so
    that a change of the machine's load between functions falls on all of them: their ratios
    hold under load where back-to-back medians do not."""
    enable_history()
    for fn in fns.values():
        _run(fn)                                          # cold: compiled here, not counted
    sums = {name: [] for name in fns}
    for _ in range(max(1, repeats)):
        for name, fn in fns.items():
            dr.kernel_history_clear()
            _run(fn)
            hist = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
            sums[name].append(sum(k.get("execution_time", 0.0) for k in hist))
    dr.kernel_history_clear()
    return {name: statistics.median(v) for name, v in sums.items()}
