"""``dsm perf`` (5b) and (5c): a sweep run in two ``[timing]`` modes in one bench run, each
twice in turn so that both read warm kernel caches: kernel launches, measuring time (wall and
CPU) and the rows compared count for count. (5b): ``lookups = "per_case"`` against
``"wavefront"`` (dsm.experiment.wavefront); (5c): ``builds = "alone"`` against ``"together"``
(a sweep's small maps built as one wavefront, dsm.experiment.stacks)."""
from __future__ import annotations

from pathlib import Path

# a sweep of many parameter values per scheme: where a map's cases share their kernels
LOOKUP_SWEEP = {
    "experiment": {"name": "bench_lookups"}, "camera": {"resolution": [256, 256]},
    "scene": [{"builtin": "plane_box"}, {"builtin": "l_shape"}],
    "light": [{"type": "directional", "direction": [-0.4, -0.3, -1.0]}],
    "map": {"resolution": [256, 1024], "filter": ["nearest", "pcf_bilinear"]},
    "scheme": [{"name": "constant", "bias": [f"{b} texel" for b in (0.25, 0.5, 1, 1.5, 2, 3, 4, 6)]},
               {"name": "normal_offset", "offset": [f"{b} texel" for b in (0.5, 1, 1.5, 2)]},
               {"name": "slope_scaled", "bias": ["0.5 texel", "1 texel"], "slope": [0.5, 1.0, 2.0]}],
    "timing": {"repeats": 3}}

# a resolution sweep of every view kind, with and without culling: where a light's small maps stack
BUILD_SWEEP = {
    "experiment": {"name": "bench_builds"}, "camera": {"resolution": [128, 128]},
    "scene": [{"builtin": "plane_box"}, {"builtin": "room"}],
    "light": [{"type": "scene"}, {"type": "spot", "position": [-2.0, 2.5, 2.6], "target": [0.0, 0.0, 0.0],
                                  "cutoff": 40}, {"type": "point", "position": [0.6, -0.8, 2.2]}],
    "map": {"resolution": [64, 128, 256, 512], "view": ["dual_paraboloid", "cube"]},
    "scheme": [{"name": "constant"}, {"name": "slope_scaled"}, {"name": "midpoint"},
               {"name": "dual", "culling": ["none", "back_closed"]}],
    "timing": {"repeats": 3}}

# columns that measure the machine or the mode itself, not the method
_MODE_COLUMNS = ("_ms", "_mb", "kernels_compiled", "lookup_shared", "build_shared")


def _one(cfg, field: str, mode: str, out: Path) -> dict:
    """One run of ``cfg`` with ``[timing]`` field ``field`` set to ``mode``: its launches, measuring seconds and rows."""
    import dataclasses

    from ..experiment.runner import Runner
    res = Runner(dataclasses.replace(cfg, **{field: mode}), out, progress=False, keep_images=False).run()
    t = res.run["timing"]
    rows = [{k: v for k, v in r.items() if not any(m in k for m in _MODE_COLUMNS)} for r in res.rows]
    waves = [m["lookup_wave_ms"] for m in res.run["maps"] if m.get("lookup_wave_ms") is not None]
    return {"launches": t["kernel_launches"], "measure_s": t["measure_s"], "measure_cpu_s": t["measure_cpu_s"],
            "case_kernel_ms": sum(r["lookup_ms"] for r in res.rows) if mode == "per_case" else None,
            "wave_kernel_ms": sum(waves) if waves else None, "rows": rows,
            "build_kernel_ms": sum(m["build_ms"] for m in res.run["maps"]),
            "maps": len(res.run["maps"]), "stacked_maps": sum(m["build_shared"] > 1 for m in res.run["maps"])}


def _alternate(config: dict, field: str, modes: tuple, out: Path) -> dict:
    """``config`` in both ``modes`` of ``field``, alternated twice; the second run of each is reported."""
    from .. import pipeline
    cfg = pipeline.prepare(config)
    runs = {}
    for i in range(2):
        for mode in modes:
            runs[mode] = _one(cfg, field, mode, out / f"{field}_{mode}_{i}")
    cases = len(runs[modes[1]]["rows"])
    same = runs[modes[0]].pop("rows") == runs[modes[1]].pop("rows")
    return {"cases": cases, **runs, "rows_equal": same}


def lookup_modes(out: Path) -> dict:
    """(5b): LOOKUP_SWEEP with each case's lookup alone and with a map's wavefront."""
    return _alternate(LOOKUP_SWEEP, "timing_lookups", ("per_case", "wavefront"), out)


def build_modes(out: Path) -> dict:
    """(5c): BUILD_SWEEP with every map built alone and with a light's small maps stacked."""
    return _alternate(BUILD_SWEEP, "timing_builds", ("alone", "together"), out)


def _section(title: str, intro: str, columns: list, rows: list) -> list:
    """A bench.md section: its title, what it measured, and a table of ``columns`` and ``rows`` (cells as text)."""
    return (["", f"## {title}", "", intro, "", "| " + " | ".join(columns) + " |", "| --- " * len(columns) + "|"]
            + ["| " + " | ".join(map(str, row)) + " |" for row in rows])


def _launches(x: dict) -> list:
    """A run's launches outside and inside the timed repeats."""
    return [x["launches"]["outside_repeats"], x["launches"]["timed_repeats"]]


def markdown(r: dict) -> list:
    """Section (5b)'s lines."""
    pc, wf = r["per_case"], r["wavefront"]
    lines = _section(
        "(5b) Lookups per case against a map's wavefront",
        "The same sweep (`dsm.perf.bench_modes.LOOKUP_SWEEP`, many parameter values per scheme) run with "
        "`[timing] lookups = \"per_case\"` and `\"wavefront\"`, each twice in turn; the second run of each. "
        "Launches from Dr.Jit's kernel history; times are the process's wall clock and CPU seconds measuring.",
        ["lookups", "launches outside the timed repeats", "launches in them", "measuring s (wall)", "measuring CPU s"],
        [[name, *_launches(x), f"{x['measure_s']:.1f}", f"{x['measure_cpu_s']:.1f}"]
         for name, x in (("per_case", pc), ("wavefront", wf))])
    lines += ["", f"Kernel time of every case's lookup, summed: {pc['case_kernel_ms']:.1f} ms one case at a "
                  f"time (per_case), {wf['wave_kernel_ms']:.1f} ms as the maps' wavefronts (their outputs also hold "
                  "each case's attached-shadow lookup and plane mask)."]
    lines += ["", f"{r['cases']} cases. Timed launches per_case / wavefront: "
                  f"{pc['launches']['timed_repeats'] / max(1, wf['launches']['timed_repeats']):.2f}x; measuring CPU "
                  f"{pc['measure_cpu_s'] / wf['measure_cpu_s']:.2f}x; every count and rate equal: {r['rows_equal']}."]
    return lines


def markdown_builds(r: dict) -> list:
    """Section (5c)'s lines."""
    al, tg = r["alone"], r["together"]
    lines = _section(
        "(5c) Maps built alone against a sweep's small maps built together",
        "The same sweep (`dsm.perf.bench_modes.BUILD_SWEEP`: two scenes, a directional, spot and point light, "
        "dual-paraboloid and cube views, R = 64 to 512, with and without culling) run with `[timing] builds = "
        "\"alone\"` and `\"together\"`, each twice in turn; the second run of each. Launches from Dr.Jit's "
        "kernel history; build kernel time summed over the maps (a stacked map's is its share of its stack's); "
        "measuring times are the process's wall clock and CPU seconds.",
        ["builds", "maps stacked", "launches outside the timed repeats", "launches in them",
         "build kernel ms, summed", "measuring s (wall)", "measuring CPU s"],
        [[name, f"{x['stacked_maps']} of {x['maps']}", *_launches(x), f"{x['build_kernel_ms']:.1f}",
          f"{x['measure_s']:.1f}", f"{x['measure_cpu_s']:.1f}"] for name, x in (("alone", al), ("together", tg))])
    lines += ["", f"{r['cases']} cases. Timed launches alone / together: "
                  f"{al['launches']['timed_repeats'] / max(1, tg['launches']['timed_repeats']):.2f}x; build kernel "
                  f"time {al['build_kernel_ms'] / max(tg['build_kernel_ms'], 1e-9):.2f}x; measuring CPU "
                  f"{al['measure_cpu_s'] / tg['measure_cpu_s']:.2f}x; every count and rate equal: {r['rows_equal']}."]
    return lines
