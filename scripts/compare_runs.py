"""The two halves of scripts/compare-commits.

``run OUT``: in the current checkout (put it first on PYTHONPATH), run every experiment at its
smoke size, the default experiment, a tiled run, a run under ``--cluster local`` and
``dsm tune experiments/tune.toml`` into OUT/<name>/, ``dsm grad`` on every experiments/gradient/*.toml
(with DSM_COMPARE_GRAD=1) and ``dsm benchmark`` at its test size
(its cases written as OUT/benchmark/cases.csv).
``compare A B``: the same runs of two checkouts, every CSV column compared row by row except
what depends on the machine or the kernel cache; prints one line per run and the differences.
"""
from __future__ import annotations

import csv
import dataclasses
import os
import subprocess
import sys
from pathlib import Path

# columns that measure the machine, not the method: by their unit's suffix, or a word in the name
# (a suffix only: "_s" inside a name would also drop n_gt_shadowed, n_acne_self, n_seam, texel_size)
# (map_bytes and page_table_bytes are counts of the method, compared; a peak in bytes is the machine's)
MACHINE_SUFFIXES = ("_ms", "_mb", "_s")
MACHINE_WORDS = ("kernels_compiled", "time", "seconds", "peak")


def _machine(col: str) -> bool:
    return col.endswith(MACHINE_SUFFIXES) or any(w in col for w in MACHINE_WORDS)


def _smoke(cfg):
    """A config at the smoke size of tests/test_experiments.py."""
    return dataclasses.replace(cfg, camera_resolution=(48, 48), timing_repeats=1,
                               map=dataclasses.replace(cfg.map, resolution=(32,),
                                                       texels=(6 * 32 ** 2,) if cfg.map.texels else ()))


def run_all(out: Path):
    """Every run of the comparison, into out/<name>/ (a run that cannot run is noted, not fatal).
    ``out`` starts empty: the kit refuses to run into an old run's folder."""
    import shutil

    import dsm
    from dsm.config import read as config
    from dsm.cli import DEFAULT_CONFIG
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for path in sorted(Path("experiments").glob("*.toml")):
        cfg = config.load(path)
        if cfg.raw.get("tune"):
            from dsm.tune.tuner import tune
            try:
                tune(cfg, out=out / f"tune-{path.stem}")
            except Exception as e:                 # noqa: BLE001 (every scene absent: recorded)
                print(f"{path.name}: {type(e).__name__}: {e}", file=sys.stderr)
            continue
        try:
            dsm.run(_smoke(cfg), out=out / f"smoke-{path.stem}")
        except Exception as e:                     # noqa: BLE001 (every scene absent: recorded)
            print(f"{path.name}: {type(e).__name__}: {e}", file=sys.stderr)
    dsm.run(DEFAULT_CONFIG, out=out / "default")
    tiled = {"experiment": {"name": "tiled"}, "camera": {"resolution": [96, 96]}, "scene": [{"builtin": "plane_box"}],
             "map": {"resolution": 512}, "memory": {"budget_mb": 1}, "timing": {"repeats": 1},
             "scheme": [{"name": "dual", "culling": "back_closed"}, {"name": "constant"}]}
    dsm.run(tiled, out=out / "tiled")
    cmd = [sys.executable, "-m", "dsm.cli", "run", "experiments/point_views.toml", "--out", str(out / "cluster"),
           "--cluster", "local"]
    subprocess.run(cmd, check=False)
    # every shipped gradient experiment: its selfcheck.csv (and whatever other CSV dsm grad writes); at their
    # full size (about 15 CPU minutes each), so only with DSM_COMPARE_GRAD=1
    grads = sorted(Path("experiments/gradient").glob("*.toml")) if os.environ.get("DSM_COMPARE_GRAD") == "1" else []
    for path in grads:
        subprocess.run([sys.executable, "-m", "dsm.cli", "grad", str(path), "--out", str(out / f"grad-{path.stem}")],
                       check=False)
    # dsm benchmark at its test size: its cases as a CSV, so they compare as every run does
    bench = out / "benchmark"
    flags, env = _test_size()
    subprocess.run([sys.executable, "-m", "dsm.cli", "benchmark", "--out", str(bench / "run"), *flags], check=False,
                   env=env)
    _cases_csv(bench / "run" / "results.json", bench / "cases.csv")


def _test_size() -> tuple:
    """The flags and environment that run this checkout's benchmark at its test size: --size test, or the
    DSM_BENCHMARK_SIZE that a checkout from before --size read (compare-commits runs this script in both)."""
    helped = subprocess.run([sys.executable, "-m", "dsm.cli", "benchmark", "--help"], capture_output=True, text=True)
    if "--size" in helped.stdout:
        return ["--size", "test"], dict(os.environ)
    return [], {**os.environ, "DSM_BENCHMARK_SIZE": "test"}


def _cases_csv(results_json: Path, csv_path: Path):
    """The benchmark's cases (results.json) as a CSV with one row per case (nothing when absent)."""
    import json
    if not results_json.exists():
        return
    cases = json.loads(results_json.read_text())["cases"]
    cols = sorted({k for c in cases for k in c if not isinstance(c[k], (dict, list))})
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(cases)


def _rows(path: Path) -> list:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _same_number(a: str, b: str) -> bool:
    """Two cells holding one number, one written to 6 significant digits and one exactly."""
    try:
        return f"{float(a):.6g}" == f"{float(b):.6g}"
    except ValueError:
        return False


def compare_csv(a: Path, b: Path) -> list:
    """Differences between two CSV files of the same run (machine columns left out)."""
    ra, rb = _rows(a), _rows(b)
    if len(ra) != len(rb):
        return [f"{a.name}: {len(ra)} rows against {len(rb)}"]
    diffs = []
    if ra and set(ra[0]) != set(rb[0]):
        # a column only one side has (a new metric) is no difference of the values both hold
        print(f"    {a.name}: columns only in A {sorted(set(ra[0]) - set(rb[0]))}, only in B "
              f"{sorted(set(rb[0]) - set(ra[0]))}; the common ones compared")
    for i, (x, y) in enumerate(zip(ra, rb)):
        for k in set(x) & set(y):
            if not _machine(k) and x[k] != y[k] and not _same_number(x[k], y[k]):
                diffs.append(f"{a.name} row {i} ({x.get('case', '')}) {k}: {x[k]!r} against {y[k]!r}")
    return diffs


def compare_all(a: Path, b: Path) -> int:
    """Print one line per run; 0 when every compared value agrees."""
    bad = 0
    for run_a in sorted(p for p in a.iterdir() if p.is_dir()):
        run_b = b / run_a.name
        files = sorted(run_a.glob("*.csv")) + [p for p in [run_a / "tuned.toml"] if p.exists()]
        diffs = [] if run_b.is_dir() else [f"{run_a.name} missing in {b}"]
        for f in files:
            g = run_b / f.name
            if not g.exists():
                diffs.append(f"{f.name} missing in {run_b}")
            elif f.suffix == ".csv":
                diffs += compare_csv(f, g)
            elif f.read_text() != g.read_text():
                diffs.append(f"{f.name} differs")
        print(f"{run_a.name}: {len(files)} files, " + ("identical" if not diffs else f"{len(diffs)} differences"))
        for d in diffs[:20]:
            print("   ", d)
        bad += bool(diffs)
    return 1 if bad else 0


if __name__ == "__main__":
    if sys.argv[1] == "run":
        run_all(Path(sys.argv[2]))
    else:
        sys.exit(compare_all(Path(sys.argv[2]), Path(sys.argv[3])))
