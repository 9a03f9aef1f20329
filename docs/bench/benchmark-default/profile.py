"""Where dsm benchmark's CPU seconds go: each stage wrapped with a wall and CPU clock (this
process's threads and its finished children)."""
import json, resource, sys, time
from collections import defaultdict
from pathlib import Path

def cpu():
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ru.ru_utime + ru.ru_stime

acc = defaultdict(lambda: [0.0, 0.0, 0])
stack = []

def wrap(mod, name, label):
    fn = getattr(mod, name)
    def inner(*a, **k):
        t, c = time.perf_counter(), cpu()
        stack.append(label)
        try:
            return fn(*a, **k)
        finally:
            stack.pop()
            dt, dc = time.perf_counter() - t, cpu() - c
            if label not in stack:      # outermost of its label only
                acc[label][0] += dt; acc[label][1] += dc; acc[label][2] += 1
    setattr(mod, name, inner)

import dsm
from dsm.benchmark import results, render, perceptual, page, figure
from dsm.report import publish
from dsm.experiment import runner as runner_mod

orig_run = dsm.run
def run(config, *a, **k):
    t, c = time.perf_counter(), cpu()
    try:
        return orig_run(config, *a, **k)
    finally:
        acc["motion runs (flicker)"][0] += time.perf_counter() - t; acc["motion runs (flicker)"][1] += cpu() - c
        acc["motion runs (flicker)"][2] += 1
dsm.run = run
wrap(results, "measured", "depth/prefiltered runs")
from dsm import pipeline
wrap(pipeline, "moment_map", "  of which: moment maps (timed repeats included)")
from dsm.experiment import builds
wrap(builds.Builds, "timed", "  of which: map builds (timed repeats)")
wrap(publish, "write_report", "  of which: report (write_report)")
wrap(render, "light_setups", "render light setups (exact side)")
wrap(render, "case_renders", "renders (shaded, exact)")
wrap(perceptual, "mean_flip", "FLIP")
wrap(page, "write_page", "page + figure")

size, out = sys.argv[1], Path(sys.argv[2])
version = sys.argv[3] if len(sys.argv) > 3 else "dsm-bench-4"      # the suite the issue measured
t0, c0 = time.perf_counter(), cpu()
doc = results.run_suite(size, None, progress=lambda m: print(m, file=sys.stderr), version=version, out=out)
results.write(doc, out)
page.write_page(doc, out)
total = (time.perf_counter() - t0, cpu() - c0)
rows = {k: {"wall_s": round(v[0], 2), "cpu_s": round(v[1], 2), "calls": v[2]} for k, v in sorted(acc.items())}
rows["total"] = {"wall_s": round(total[0], 2), "cpu_s": round(total[1], 2)}
print(json.dumps(rows, indent=1))
(out / "profile.json").write_text(json.dumps(rows, indent=1))
