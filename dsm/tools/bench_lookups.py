"""``dsm bench`` (5b): a parameter sweep run with ``[timing] lookups = "per_case"`` and with
``"wavefront"`` (dsm.experiment.wavefront) in one bench run, each twice in turn so that both
read warm kernel caches: kernel launches, measuring time (wall and CPU) and the rows compared
count for count."""
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

# columns that measure the machine or the mode itself, not the method
_MODE_COLUMNS = ("_ms", "_mb", "kernels_compiled", "lookup_shared")


def _one(cfg, mode: str, out: Path) -> dict:
    """One run of ``cfg`` in lookup mode ``mode``: its launches, measuring seconds and rows."""
    import dataclasses

    from ..experiment.runner import Runner
    res = Runner(dataclasses.replace(cfg, timing_lookups=mode), out, progress=False, keep_images=False).run()
    t = res.run["timing"]
    rows = [{k: v for k, v in r.items() if not any(m in k for m in _MODE_COLUMNS)} for r in res.rows]
    waves = [m["lookup_wave_ms"] for m in res.run["maps"] if m.get("lookup_wave_ms") is not None]
    return {"launches": t["kernel_launches"], "measure_s": t["measure_s"], "measure_cpu_s": t["measure_cpu_s"],
            "case_kernel_ms": sum(r["lookup_ms"] for r in res.rows) if mode == "per_case" else None,
            "wave_kernel_ms": sum(waves) if waves else None, "rows": rows}


def lookup_modes(out: Path) -> dict:
    """The sweep in both lookup modes, alternated twice; the second run of each is reported."""
    from .. import pipeline
    cfg = pipeline.prepare(LOOKUP_SWEEP)
    runs = {}
    for i in range(2):
        for mode in ("per_case", "wavefront"):
            runs[mode] = _one(cfg, mode, out / f"lookups_{mode}_{i}")
    cases = len(runs["wavefront"]["rows"])
    same = runs["per_case"].pop("rows") == runs["wavefront"].pop("rows")
    return {"cases": cases, **runs, "rows_equal": same}


def markdown(r: dict) -> list:
    """Section (5b)'s lines."""
    pc, wf = r["per_case"], r["wavefront"]
    lines = ["", "## (5b) Lookups per case against a map's wavefront", "",
             "The same sweep (`dsm.tools.bench_lookups.LOOKUP_SWEEP`, many parameter values per scheme) run with "
             "`[timing] lookups = \"per_case\"` and `\"wavefront\"`, each twice in turn; the second run of each. "
             "Launches from Dr.Jit's kernel history; times are the process's wall clock and CPU seconds measuring.",
             "", "| lookups | launches outside the timed repeats | launches in them | measuring s (wall) | "
                 "measuring CPU s |", "| --- | --- | --- | --- | --- |"]
    for name, x in (("per_case", pc), ("wavefront", wf)):
        kl = x["launches"]
        lines.append(f"| {name} | {kl['outside_repeats']} | {kl['timed_repeats']} | {x['measure_s']:.1f} | "
                     f"{x['measure_cpu_s']:.1f} |")
    lines += ["", f"Kernel time of every case's lookup, summed: {pc['case_kernel_ms']:.1f} ms one case at a "
                  f"time (per_case), {wf['wave_kernel_ms']:.1f} ms as the maps' wavefronts (their outputs also hold "
                  "each case's attached-shadow lookup and plane mask)."]
    lines += ["", f"{r['cases']} cases. Timed launches per_case / wavefront: "
                  f"{pc['launches']['timed_repeats'] / max(1, wf['launches']['timed_repeats']):.2f}x; measuring CPU "
                  f"{pc['measure_cpu_s'] / wf['measure_cpu_s']:.2f}x; every count and rate equal: {r['rows_equal']}."]
    return lines
