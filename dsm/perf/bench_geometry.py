"""``dsm perf`` (7): what a map build and one frame cost against the scene's triangles.

The meshes are the real terrain of :mod:`dsm.scenes.terrain` (the Jacksboro fault DEM)
resampled bilinearly to grids of about 1e4 to 1e6 triangles by default (``--geometry`` takes any
sizes; docs/bench/cpu-llvm-geometry goes to 1e7), written as binary PLY and loaded
as a user's mesh file (here). Per mesh: the first-layer build and one frame (:func:`bench.frame_cost`:
the map plus every single-layer lookup) as kernel and wall time, in the bench's process
(:func:`dsm.perf.bench.geometry_cost`); and the peak
resident memory (Linux's VmHWM) of one-case ``dsm run``s on the mesh in their own processes,
against ``dsm plan``'s estimate for the same config (run.json's ``peak_bytes_est``), at the
set-up the plan's constants were fitted to and at one they never saw. The exponent of time
against triangles is fitted in log-log as for resolutions, with the slope between consecutive sizes.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

TRIANGLES = (10_000, 100_000, 1_000_000)


def grid_for(triangles: int, aspect: float) -> tuple:
    """(rows, cols) of a grid of samples whose 2 (rows - 1) (cols - 1) triangles are nearest
    ``triangles``, cols / rows about ``aspect``."""
    rows = max(2, int(round((triangles / 2 / aspect) ** 0.5)) + 1)
    cols = max(2, int(round(triangles / 2 / (rows - 1))) + 1)
    return rows, cols


def resampled_terrain(triangles: int) -> tuple:
    """(vertices (n, 3) float64 in metres, faces (m, 3)) of the DEM terrain bilinearly resampled to
    about ``triangles`` triangles over the same extent (wound counter-clockwise from above)."""
    from ..scenes import terrain
    verts, _ = terrain.mesh(1)
    cols0 = int(np.count_nonzero(verts[:, 1] == verts[0, 1]))        # samples of the DEM's first row
    rows0 = len(verts) // cols0
    z0 = verts[:, 2].reshape(rows0, cols0)
    x0, y0 = verts[:cols0, 0], verts[::cols0, 1]                      # x east ascending, y north descending
    rows, cols = grid_for(triangles, (cols0 - 1) / (rows0 - 1))
    fr, fc = np.linspace(0, rows0 - 1, rows), np.linspace(0, cols0 - 1, cols)
    r0, c0 = np.minimum(fr.astype(int), rows0 - 2), np.minimum(fc.astype(int), cols0 - 2)
    wr, wc = (fr - r0)[:, None], (fc - c0)[None, :]
    z = (z0[r0][:, c0] * (1 - wr) * (1 - wc) + z0[r0 + 1][:, c0] * wr * (1 - wc)
         + z0[r0][:, c0 + 1] * (1 - wr) * wc + z0[r0 + 1][:, c0 + 1] * wr * wc)
    xx, yy = np.meshgrid(np.interp(fc, np.arange(cols0), x0), np.interp(fr, np.arange(rows0), y0))
    k = np.arange(rows * cols).reshape(rows, cols)
    nw, ne, sw, se = k[:-1, :-1].ravel(), k[:-1, 1:].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel()
    faces = np.concatenate([np.stack([sw, se, ne], 1), np.stack([sw, ne, nw], 1)])
    return np.stack([xx.ravel(), yy.ravel(), z.ravel()], axis=1), faces


def write_ply(path: Path, verts: np.ndarray, faces: np.ndarray) -> int:
    """Write a binary little-endian PLY of float32 vertices and int32 triangles; the triangle count."""
    rec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rec["n"], rec["i"] = 3, faces
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(faces)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(head.encode() + np.asarray(verts, "<f4").tobytes() + rec.tobytes())
    return len(faces)


RUN_CONFIG = ('[experiment]\nname = "bench_geometry"\n[camera]\nresolution = [{camera}, {camera}]\n[[scene]]\n'
              'file = "{file}"\nup = "z"\nground = "no"\n[map]\nresolution = {R}\n[[scheme]]\nname = "constant"\n'
              '[timing]\nrepeats = 1\n[report]\nimages = "none"\n')
# (camera, map resolution) of the two runs: the first is the set-up dsm plan's per-triangle and
# per-process constants were fitted to (experiment/plan.py), so it checks the fit; the second, a
# camera and a map 16x larger, is a check the constants never saw
FITTED, HELD_OUT = (64, 256), (256, 1024)


def run_peak(ply: Path, work: Path) -> dict:
    """One-case ``dsm run``s on ``ply``, each in its own process, at the FITTED and HELD_OUT set-ups:
    their measured peak resident memory and ``dsm plan``'s estimate of it (MB), from run.json."""
    out = {}
    for tag, (camera, R) in (("", FITTED), ("check_", HELD_OUT)):
        cfg, run_dir = work / f"{ply.stem}.toml", work / f"run_{ply.stem}"
        cfg.write_text(RUN_CONFIG.format(file=ply.resolve().as_posix(), camera=camera, R=R))
        p = subprocess.run([sys.executable, "-m", "dsm", "run", str(cfg), "--out", str(run_dir), "--force"],
                           capture_output=True, text=True, timeout=1800)
        cfg.unlink()
        if p.returncode != 0:
            out[f"{tag}run_error"] = (p.stderr.strip().splitlines()[-1][:200] if p.stderr.strip()
                                      else f"exit {p.returncode}")
            continue
        run = json.loads((run_dir / "run.json").read_text())
        shutil.rmtree(run_dir)                     # the bench keeps its figures, not the run
        est, peak = run["plan"]["peak_bytes_est"], run["timing"]["measure_peak_rss_bytes"]
        out.update({f"{tag}peak_mb": peak / 2 ** 20, f"{tag}plan_peak_mb": est / 2 ** 20, f"{tag}plan_over_peak": est / peak})
    return out


def decade_slopes(triangles, ms) -> list:
    """The log-log slope between consecutive sizes: where one fitted exponent hides a bend (None
    between two sizes that resampled to one triangle count)."""
    t, m = np.log10(np.asarray(triangles, float)), np.log10(np.asarray(ms, float))
    return [float((m[i + 1] - m[i]) / (t[i + 1] - t[i])) if t[i + 1] != t[i] else None for i in range(len(t) - 1)]


def exponent_text(x: float) -> str:
    """A fitted exponent in bench.md: 3 decimals, or undefined (one size: no slope; NaN, never printed)."""
    return f"{x:.3f}" if x == x else "undefined (one size: a slope needs two)"


def markdown(g: dict) -> list:
    """The bench.md lines of section (7)."""
    tris = [r["triangles"] for r in g["rows"]]
    span = f"{min(tris):.0e}-{max(tris):.0e}".replace("e+0", "e") if tris else "no"
    lines = ["", f"## (7) Cost against geometry: the DEM terrain resampled to {span} triangles", "",
             "Build: the first layer of a 1024^2 map; frame: that map with the slope layer plus every "
             "single-layer scheme's lookup over the camera's visible pixels (as (6)). Kernel time: the kernels' "
             "own execution time; wall: Python's tracing included (kernel and wall are medians of separate "
             "calls, so on a quiet machine the wall median can fall below the kernel one). Peak: a one-case "
             f"`dsm run` on the mesh in its own process, Linux's VmHWM, against `dsm plan`'s estimate: at "
             f"{FITTED[0]}^2 camera and {FITTED[1]}^2 map, the set-up the plan's constants were fitted to, and at "
             f"{HELD_OUT[0]}^2 and {HELD_OUT[1]}^2 (*check*), one they never saw.", "",
             "| triangles | bare cast kernel ms | build kernel ms | build wall ms | frame kernel ms | "
             "frame wall ms | run peak MB | plan estimate MB | estimate / peak | check peak MB | check estimate MB "
             "| check estimate / peak |", "|---" * 12 + "|"]
    for r in g["rows"]:
        mem = " | ".join(f"{r[t + 'peak_mb']:.0f} | {r[t + 'plan_peak_mb']:.0f} | {r[t + 'plan_over_peak']:.2f}"
                         if t + "peak_mb" in r else f"{r.get(t + 'run_error', 'not measured')} | | " for t in ("", "check_"))
        lines.append(f"| {r['triangles']:,} | {r['bare_kernel_ms']:.2f} | {r['build_kernel_ms']:.2f} | "
                     f"{r['build_wall_ms']:.2f} | {r['frame_kernel_ms']:.2f} | {r['frame_wall_ms']:.2f} | {mem} |")
    e, d = {k: exponent_text(v) for k, v in g["exponents"].items()}, g.get("decade_slopes", {})
    lines += ["", "Fitted exponent of time against triangles (log-log least squares; 0: independent of the "
              f"geometry): build {e['build_kernel_ms']} (kernel), {e['build_wall_ms']} (wall); frame "
              f"{e['frame_kernel_ms']} (kernel), {e['frame_wall_ms']} (wall)."]
    if d:
        lines += ["", "Slope between consecutive sizes (kernel time; a bend the one exponent hides): build "
                  + ", ".join("-" if x is None else f"{x:.2f}" for x in d["build_kernel_ms"]) + "; frame "
                  + ", ".join("-" if x is None else f"{x:.2f}" for x in d["frame_kernel_ms"]) + "."]
    return lines
