"""``dsm perf``: what a map build and a lookup cost, as ratios measured in one run.

(1) Map build time (first layer; two layers for dual) over the time of a bare
``scene.ray_intersect`` of the same texel rays (and of the cheaper
``ray_intersect_preliminary`` the build itself uses), per resolution and scene.
(2) Lookup time of each scheme over constant bias's, beside Dou et al.'s Table 1.
(3) Peak memory of each build and lookup (Dr.Jit's allocation watermark).
Warm medians after a JIT warm-up; ``dr.sync_thread()`` around every clock read.
(4) Cost against resolution (``scaling``, up to 8192^2), each map cast in the tiles the memory
budget allows (as ``dsm plan`` sizes them), with the exponent of time against texels fitted in
log-log (1: linear in texels). (5) Throughput of a whole sweep in cases per second, run here
and on a local two-worker Ray cluster (``sweep``; needs ``dsm[cluster]``). (6) One frame: a
1024^2 map of the largest scene plus the nearest lookup of every single-layer scheme over the
visible pixels of a 1024^2 camera, timed three ways: wall clock (Python's tracing included),
kernel time (the sum of the kernels' own execution times from Dr.Jit's kernel history) and a
``dr.freeze``-recorded frame replayed (tracing removed), where freezing works. (7) Cost against
triangles (:mod:`dsm.perf.bench_geometry`). (8) Pre-filtered maps (moments and blur, lookup)
beside PCF at the same kernel width (:mod:`dsm.perf.bench_prefilter`; ``prefilter``).
A benchmark, not a test: results go to bench.md and bench.json.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.env import meshes_folder

MESHES = meshes_folder()       # the real test meshes shipped with the kit (a checkout's or a wheel's)

DOU_TABLE1 = {"constant": 6.327, "slope_scaled": 6.647, "adaptive": 7.319, "dual": 9.890}


def _scenes(meshes: Path):
    from ..config.read import SceneSpec
    from ..scenes.load import FileParams, PlaneBoxParams, TerrainParams
    out = [SceneSpec(builtin="plane_box", params=PlaneBoxParams(), label="plane_box"),
           SceneSpec(builtin="terrain", params=TerrainParams(), label="terrain")]
    # Sponza is not shipped (data/meshes/README.md): measured where a user has put a copy
    for name, up in (("mitsuba_bunny.ply", "y"), ("sponza_dabrovic.ply", "y")):
        if (meshes / name).is_file():
            out.append(SceneSpec(file=meshes / name, params=FileParams(up=up), label=Path(name).stem))
    return out


def _light_for(spec):
    """The bench's directional light for a scene: oblique over a built-in, from above a mesh."""
    from ..config.read import LightSpec
    return LightSpec("directional", direction=(-0.4, -0.3, -1.0) if spec.builtin else (0.25, -1.0, 0.15))


def _peak(timing, fn, repeats):
    """(None, Timing, peak MB above what was allocated before): outputs are dropped."""
    timing.reset_peak()
    before = timing.peak_bytes()
    _, t = timing.measure(fn, repeats)
    return None, t, (timing.peak_bytes() - before) / 2 ** 20


def tile_for(texels: int, layered: bool, budget: int) -> int:
    """The texels per pass that keep a first-layer or two-layer build within ``budget`` bytes,
    by the plan's own estimate (dsm.config.plan.MapPlan)."""
    from ..config.plan import MIN_TILE, MapPlan
    m = MapPlan("", "", "orthographic", int(round(texels ** 0.5)), 1, "none", ("z2",) if layered else (), layered,
                (), [], 0)
    room = budget - m.stored_bytes
    return int(min(texels, max(room // max(m.build_bytes_per_texel, 1), MIN_TILE)))


def fitted_exponent(texels, ms) -> float:
    """The slope of log(time) against log(texels) (least squares); NaN with fewer than two sizes."""
    if len(texels) < 2:
        return float("nan")
    return float(np.polyfit(np.log(np.asarray(texels, float)), np.log(np.asarray(ms, float)), 1)[0])


def scaling(sd, view_for, resolutions, repeats, ext, budget) -> list:
    """(4): first and two-layer build time per resolution, tiled within the budget."""
    from ..maps import shadowmap
    from ..core import timing
    rows = []
    for R in resolutions:
        view = view_for(R)
        t1 = tile_for(R * R, False, budget)
        t2 = tile_for(R * R, True, budget)
        first = timing.measure(lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, set(), tile=t1,
                                                                        extents=ext)), repeats)[1]
        two = timing.measure(lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, tile=t2,
                                                                      extents=ext)), repeats)[1]
        rows.append({"scene": sd.label, "resolution": R, "texels": R * R, "first_ms": first.ms, "two_ms": two.ms,
                     "first_tiles": -(-R * R // t1), "two_tiles": -(-R * R // t2),
                     "ns_per_texel_first": first.ms * 1e6 / (R * R), "ns_per_texel_two": two.ms * 1e6 / (R * R)})
    return rows


SWEEP_CONFIG = {
    "experiment": {"name": "bench_sweep"}, "camera": {"resolution": [64, 64]},
    "scene": [{"builtin": "plane_box"}, {"builtin": "plane"}, {"builtin": "plane_box"}, {"builtin": "plane"}],
    "light": [{"type": "directional", "direction": [-0.4, -0.3, -1.0]}],
    "map": {"resolution": [64, 128]},
    "scheme": [{"name": "constant", "bias": ["1 texel", "3 texel"]}, {"name": "slope_scaled"},
               {"name": "midpoint"}, {"name": "dual"}],
    "timing": {"repeats": 1}}


def sweep_throughput(out: Path, workers: int = 2) -> dict:
    """(5): a small sweep's cases per second run here, then on a local Ray cluster of ``workers``
    (Ray's start-up excluded: the cluster is started before the clock); equal rows checked."""
    import time

    from .. import pipeline
    from ..report import io as report
    from ..experiment.runner import Runner
    cfg = pipeline.prepare(SWEEP_CONFIG)
    t0 = time.perf_counter()
    local = Runner(cfg, out / "sweep_local", progress=False, keep_images=False).run()
    local_s = time.perf_counter() - t0
    row = {"cases": len(local.rows), "local_s": local_s, "local_cases_per_s": len(local.rows) / local_s,
           "kernel_launches": local.run["timing"]["kernel_launches"]}    # issue 33's count, in this run
    try:
        import ray
    except ImportError:
        return {**row, "ray": "not installed (pip install 'dsm[cluster]')"}
    from ..experiment import cluster
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level="error")
    try:
        t0 = time.perf_counter()
        res = cluster.run(cfg, out / "sweep_ray", "local", progress=False)
        ray_s = time.perf_counter() - t0
    finally:
        ray.shutdown()
    skip = {"build_ms", "build_first_ms", "build_compile_ms", "build_peak_mb", "lookup_ms", "lookup_compile_ms",
            "lookup_kernels_compiled", "reference_ms", "fit_ms"}
    same = [{k: v for k, v in r.items() if k not in skip} for r in report.read_csv(out / "sweep_local" / "metrics.csv")] \
        == [{k: v for k, v in r.items() if k not in skip} for r in report.read_csv(out / "sweep_ray" / "metrics.csv")]
    return {**row, "workers": workers, "ray_s": ray_s, "ray_cases_per_s": len(res.rows) / ray_s,
            "speedup": local_s / ray_s, "rows_equal": same, "nodes": res.run["nodes"]}


FRAME_SCHEMES = ("none", "constant", "slope_scaled", "normal_angle", "normal_offset", "receiver_plane", "adaptive",
                 "adaptive_tap", "combined")     # every scheme that reads one layer (no z2, no culling)


TABLE_FIELDS = ("tri_pos", "face_offset", "by_id")   # spawn.ShapeTables' arrays beside its pair


def frame_cost(spec, light, R: int = 1024, camera: int = 1024, repeats: int = 5, frozen: bool = True) -> dict:
    """(6): one frame's map build and single-layer lookups, as wall, kernel and (``frozen``) frozen time."""
    import drjit as dr
    import mitsuba as mi

    from ..maps import shadowmap
    from ..scenes import spawn
    from ..scenes import load as scenes
    from .. import schemes
    from ..core import timing
    from ..scenes.gbuffer import cast
    from ..pipeline import make_view, points_np
    sd = scenes.load(spec, (camera, camera))
    gb = cast(sd.scene, sd.sensor, camera, camera)
    pix = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    p, n = dr.gather(mi.Point3f, gb.p, pix), dr.gather(mi.Vector3f, gb.n, pix)
    dr.eval(p, n)
    view = make_view(light, R, points_np(p), sd.bbox)
    mods = [schemes.get(name) for name in FRAME_SCHEMES]
    needs = set().union(*(set(m.NEEDS) for m in mods))
    rays = view.texel_rays(0, R * R)
    dr.eval(rays)

    def bare():
        """The bare cast: the preliminary intersection of every texel ray (distances only)."""
        return (sd.scene.ray_intersect_preliminary(rays, coherent=spawn.COHERENT).t,)

    ext = spawn.shape_extents(sd.scene)                   # made once per scene, as the runner does
    frame, state = _frame_fn(sd, view, mods, needs, ext)
    args = (sd.scene, state, p, n)
    wall = timing.measure(lambda: frame(*args), repeats)[1]
    kernel_ms, kernels = timing.kernel_ms(lambda: frame(*args), repeats)
    first = lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, set(), extents=ext))   # noqa: E731
    row = {"scene": spec.label, "map": R, "camera": camera,
           "receivers": dr.width(p), "schemes": list(FRAME_SCHEMES), "wall_ms": wall.ms,
           "compile_ms": wall.compile_ms, "kernel_ms": kernel_ms, "kernels": kernels,
           "bare_kernel_ms": timing.kernel_ms(bare, repeats)[0], "bare_wall_ms": timing.measure(bare, repeats)[1].ms,
           "build_kernel_ms": timing.kernel_ms(first, repeats)[0], "build_wall_ms": timing.measure(first, repeats)[1].ms}
    if frozen:
        row.update(_frozen_ms(frame, args, repeats))
    return row


def _frame_fn(sd, view, mods, needs, ext) -> tuple:
    """(frame function of (scene, state, p, n), state): the view's and the shape tables' Dr.Jit
    values are the frame's inputs, since a frozen function sees only its arguments."""
    import copy

    import drjit as dr

    from ..maps import lookup, shadowmap
    from ..maps.receiver import Receiver
    from ..scenes import spawn
    prms = [m.Params() for m in mods]
    state = {k: v for k, v in vars(view).items() if dr.is_array_v(v)}
    state["tables"] = {"pair": tuple(ext), **{k: getattr(ext, k) for k in TABLE_FIELDS}}

    def frame(scene, state, p, n):
        """One frame from ``state`` (the view's and tables' values): the map built, each scheme's lookup, and z1."""
        state = dict(state)
        tab = state.pop("tables")
        v = copy.copy(view)
        vars(v).update(state)
        tables = spawn.ShapeTables(tab["pair"])
        for k in TABLE_FIELDS:
            setattr(tables, k, tab[k])
        smap = shadowmap.build(scene, v, needs, extents=tables)
        rx = Receiver.make(v, p, n, sd.diagonal)
        return tuple(lookup.visibility(m, prm, rx, smap)[0] for m, prm in zip(mods, prms)) + (smap.z1,)
    return frame, state


def _frozen_ms(frame, args, repeats) -> dict:
    """The frame recorded once by ``dr.freeze`` and replayed: the median replay (ms) and whether a
    replay equals a traced frame, or why freezing failed."""
    import time

    import drjit as dr
    try:
        frozen = dr.freeze(frame)
        for _ in range(3):                                # record, then replays
            out = frozen(*args)
            dr.eval(*out)
        ref = frame(*args)
        dr.eval(*ref)
        same = all(bool(dr.all(a == b)) for a, b in zip(out, ref))
        ts = []
        for _ in range(repeats):
            dr.sync_thread()
            t0 = time.perf_counter()
            out = frozen(*args)
            dr.eval(*out)
            dr.sync_thread()
            ts.append((time.perf_counter() - t0) * 1e3)
        return {"frozen_ms": float(np.median(ts)), "frozen_same": same}
    except Exception as exc:                              # noqa: BLE001 (reported, not hidden)
        return {"frozen_ms": None, "frozen_error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:200]}"}


def mesh_cost(ply: Path, label: str, triangles: int, R: int, camera: int, repeats: int) -> dict:
    """The first-layer build (kernel and wall time) and one frame (:func:`frame_cost`) on one mesh."""
    from ..config.read import LightSpec, SceneSpec
    from ..scenes.load import FileParams
    spec = SceneSpec(file=ply, params=FileParams(up="z", ground="no"), label=label)
    light = LightSpec("directional", direction=(0.25, -1.0, 0.15))
    f = frame_cost(spec, light, R=R, camera=camera, repeats=repeats, frozen=False)
    return {"scene": label, "triangles": triangles, "map": R, "camera": camera,
            "build_kernel_ms": f["build_kernel_ms"], "build_wall_ms": f["build_wall_ms"],
            "frame_kernel_ms": f["kernel_ms"], "frame_wall_ms": f["wall_ms"], "bare_kernel_ms": f["bare_kernel_ms"]}


def geometry_cost(out: Path, triangles=None, R: int = 1024, camera: int = 512, repeats: int = 3,
                  memory: bool = True) -> dict:
    """(7) (:mod:`dsm.perf.bench_geometry`): rows per mesh size (default TRIANGLES) and the
    exponents of build and frame time against triangles."""
    from .bench_geometry import TRIANGLES, decade_slopes, resampled_terrain, run_peak, write_ply
    triangles = TRIANGLES if triangles is None else triangles
    work = out / "geometry"
    rows = []
    for n in triangles:
        ply = work / f"terrain_{n}.ply"
        tris = write_ply(ply, *resampled_terrain(n))
        row = mesh_cost(ply, f"terrain_{tris}", tris, R, camera, repeats)
        if memory:
            row.update(run_peak(ply, work))
        rows.append(row)
        ply.unlink()
    if work.is_dir() and not any(work.iterdir()):
        work.rmdir()
    tri = [r["triangles"] for r in rows]
    keys = ("build_kernel_ms", "build_wall_ms", "frame_kernel_ms", "frame_wall_ms")
    exps = {k: fitted_exponent(tri, [r[k] for r in rows]) for k in keys}
    return {"rows": rows, "exponents": exps, "decade_slopes": {k: decade_slopes(tri, [r[k] for r in rows]) for k in keys}}


def meshes_problem(meshes) -> str | None:
    """Why ``meshes`` cannot be the folder of real test meshes (None if it can, or is not given)."""
    if meshes is None:
        return None
    path = Path(meshes)
    if not path.exists():
        return f"--meshes {path}: no such folder (the real test meshes; default {MESHES})"
    if not path.is_dir():
        return f"--meshes {path}: is a file, not a folder of meshes (default {MESHES})"
    return None


def run_bench(out: Path, resolutions=(256, 512, 1024, 2048, 4096), repeats: int = 5, meshes: Path | None = None,
              variant: str | None = None, scaling_resolutions=(), sweep: bool = False, frame: bool = True,
              geometry=(), prefilter: bool = True, resume: bool = False) -> dict:
    """Measure (1) to (8) (scaling, sweep, frame, geometry and prefilter as asked), write bench.md and
    bench.json into ``out`` as each section finishes; ``resume``: the sections an interrupted perf
    there kept are taken as they are (Mismatch where it was asked for other sections); the dict."""
    import drjit as dr

    from ..core import env, timing
    from ..config.plan import physical_memory

    problem = meshes_problem(meshes)
    if problem:          # the real-mesh rows would be dropped without a word
        raise FileNotFoundError(problem)
    variant = env.use_variant(variant)
    asked = {"resolutions": list(resolutions), "scaling_resolutions": list(scaling_resolutions), "repeats": repeats,
             "meshes": str(Path(meshes).resolve()) if meshes else None, "variant": variant, "sweep": sweep,
             "frame": frame, "geometry": list(geometry), "prefilter": prefilter}
    kept = resumed(out, asked) if resume else None
    timing.enable_history()
    meshes = Path(meshes) if meshes else MESHES
    budget = physical_memory() // 4           # the default memory budget ([memory] budget_mb)
    result = {"variant": variant, "threads": dr.thread_count(), "repeats": repeats, "builds": [], "lookups": [],
              "dou_table1_ms": DOU_TABLE1, "scaling": [], "exponents": {}, "budget_mb": budget / 2 ** 20,
              "versions": env.versions(), "machine": env.machine(), "asked": asked, "sections": [], "complete": False}
    section = lambda name, fn: _section(out, result, kept, name, fn)
    for spec in _scenes(meshes):
        section(f"builds and lookups of {spec.label}",
                lambda: dict(zip(SCENE_KEYS, _scene_bench(spec, resolutions, repeats, scaling_resolutions, budget))))
    if frame:
        specs = _scenes(meshes)
        section("frame", lambda: {"frame": frame_cost(specs[-1], _light_for(specs[-1]), repeats=max(repeats, 5))})
    if geometry:
        section("geometry", lambda: {"geometry": geometry_cost(out, tuple(geometry), repeats=max(1, min(repeats, 3)))})
    if sweep:
        from .bench_modes import build_modes, lookup_modes
        section("sweep", lambda: {"sweep": sweep_throughput(out), "lookup_modes": lookup_modes(out),
                                  "build_modes": build_modes(out)})
    if prefilter:
        from .bench_prefilter import prefilter_cost
        section("prefilter", lambda: {"prefilter": prefilter_cost(repeats=repeats)})
    result["complete"] = True
    keep_section(out, result, None)
    return result


SCENE_KEYS = ("builds", "lookups", "scaling")     # a scene's section: rows added to these lists
SECTION_KEYS = {"frame": ("frame",), "geometry": ("geometry",), "sweep": ("sweep", "lookup_modes", "build_modes"),
                "prefilter": ("prefilter",)}


class Mismatch(ValueError):
    """The interrupted perf in the folder was asked for other sections than this one."""


def resumed(out: Path, asked: dict) -> dict:
    """The interrupted perf's bench.json in ``out`` (Mismatch where it was asked otherwise, or is none)."""
    try:
        kept = json.loads((Path(out) / "bench.json").read_text())
    except (OSError, ValueError):
        raise Mismatch(f"{Path(out) / 'bench.json'} cannot be read") from None
    if not isinstance(kept, dict) or kept.get("complete") is not False:
        raise Mismatch("it holds no interrupted dsm perf (bench.json is complete or from an older dsm)")
    rows = [r for k in SCENE_KEYS for r in (kept.get(k) if isinstance(kept.get(k), list) else [None])]
    if not (isinstance(kept.get("sections"), list) and all(isinstance(x, str) for x in kept["sections"])
            and all(isinstance(r, dict) and isinstance(r.get("scene"), str) for r in rows)):
        raise Mismatch(f"{Path(out) / 'bench.json'} is damaged (its sections or rows are not a dsm perf's)")
    differs = [k for k in asked if (kept.get("asked") or {}).get(k) != asked[k]]
    if differs:
        k = differs[0]
        raise Mismatch(f"its perf was asked {k} = {(kept.get('asked') or {}).get(k)!r}, this one {asked[k]!r}")
    return kept


def _section(out: Path, result: dict, kept: dict | None, name: str, fn):
    """One section: taken from ``kept`` where the interrupted perf finished it, else measured; kept at once."""
    if kept is not None and name in kept["sections"]:
        if name in SECTION_KEYS:
            part = {k: kept[k] for k in SECTION_KEYS[name] if k in kept}
        else:               # a scene's rows, by its label
            label = name.removeprefix("builds and lookups of ")
            part = {k: [r for r in kept[k] if r["scene"] == label] for k in SCENE_KEYS}
    else:
        part = fn()
    for k, v in part.items():
        result[k] = result[k] + v if k in SCENE_KEYS else v
    result["exponents"] = _exponents(result["scaling"])
    keep_section(out, result, name)


def keep_section(out: Path, result: dict, section: str | None):
    """bench.json and bench.md rewritten (atomically) with ``section`` finished, so a Ctrl-C or a
    kill keeps every section measured before it; None: the bench is complete."""
    from ..report import io as report_io
    if section is not None:
        result["sections"].append(section)
    out.mkdir(parents=True, exist_ok=True)
    report_io.write_text(out / "bench.json", json.dumps(result, indent=2))
    report_io.write_text(out / "bench.md", markdown(result))


def kept_sections(out: Path) -> list | None:
    """The sections an interrupted perf kept in ``out``/bench.json (None: no bench.json)."""
    try:
        sections = json.loads((Path(out) / "bench.json").read_text()).get("sections", [])
    except (OSError, ValueError, AttributeError):
        return None
    return [str(x) for x in sections] if isinstance(sections, list) else None


def _exponents(scale) -> dict:
    """Per scene of the scaling rows: the fitted exponent of first- and two-layer time against texels."""
    out = {}
    for label in dict.fromkeys(r["scene"] for r in scale):
        rows = [r for r in scale if r["scene"] == label]
        out[label] = {k: fitted_exponent([r["texels"] for r in rows], [r[k + "_ms"] for r in rows])
                      for k in ("first", "two")}
    return out


def _scene_bench(spec, resolutions, repeats, scaling_resolutions, budget) -> tuple:
    """(build rows, lookup rows, scaling rows) of one scene: (1), (2) at 1024^2 and (4)."""
    import drjit as dr
    import mitsuba as mi

    from ..scenes import spawn
    from ..scenes import load as scenes
    from ..pipeline import closedness, cull_modes, make_view, points_np
    from ..scenes.gbuffer import cast
    sd = scenes.load(spec, (512, 512))
    lt = _light_for(spec)
    gb = cast(sd.scene, sd.sensor, 512, 512)
    pix = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    ext = spawn.shape_extents(sd.scene)          # once per scene, outside the timed builds
    per_shape = cull_modes("back_closed", closedness(sd)[0])   # dual's default: culls closed meshes only
    p, n = dr.gather(mi.Point3f, gb.p, pix), dr.gather(mi.Vector3f, gb.n, pix)
    builds, lookups = [], []
    lookup_R = min(resolutions, key=lambda R: (abs(R - 1024), R))     # (2) and (3) at 1024^2, else the nearest
    for R in resolutions:
        view = make_view(lt, R, points_np(p), sd.bbox)
        builds.append(_build_row(sd, spec.label, view, R, repeats, ext, per_shape))
        if R == lookup_R:
            lookups += [{**row, "resolution": R} for row in _lookup_rows(sd, spec.label, view, p, n, ext, repeats)]
    scale = []
    if scaling_resolutions:
        scale = scaling(sd, lambda R: make_view(lt, R, points_np(p), sd.bbox), scaling_resolutions,
                        max(1, min(repeats, 3)), ext, budget)
    return builds, lookups, scale


def _build_row(sd, label, view, R, repeats, ext, per_shape) -> dict:
    """(1) at one resolution: the builds against a full and a bare cast of the same texel rays,
    wall clock back to back and kernel time interleaved (one call of each in turn per repeat)."""
    import drjit as dr
    import mitsuba as mi

    from ..maps import shadowmap
    from ..scenes import spawn
    from ..core import timing
    rays = view.texel_rays(0, R * R)
    dr.eval(rays)

    def full_cast():
        """A full ``ray_intersect`` of the texel rays (the build's baseline): t, p, n."""
        si = sd.scene.ray_intersect(rays, mi.RayFlags.All, spawn.COHERENT)
        return si.t, si.p, si.n

    def bare_cast(coherent=spawn.COHERENT):
        """The preliminary intersection of the texel rays (what the build casts), distances only."""
        return (sd.scene.ray_intersect_preliminary(rays, coherent=coherent).t,)
    full = timing.measure(full_cast, repeats)[1]
    bare = timing.measure(bare_cast, repeats)[1]
    # the packet-dependent coherent traversal the builds do not use: what exactness costs
    coherent = timing.measure(lambda: bare_cast(True), repeats)[1]
    builds_of = {"first": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, set(), extents=ext)),
                 "two": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, extents=ext)),
                 "cull": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, "back_closed",
                                                                  per_shape, extents=ext))}
    (first, first_mb), (two, two_mb), (cull, cull_mb) = (_peak(timing, f, repeats)[1:] for f in builds_of.values())
    k = timing.kernel_ms_interleaved({"bare": bare_cast, **builds_of}, repeats)
    return {"scene": label, "resolution": R, "ray_intersect_ms": full.ms, "bare_ms": bare.ms,
            "bare_coherent_ms": coherent.ms, "bare_over_coherent": bare.ms / coherent.ms,
            "two_culled_ms": cull.ms, "two_culled_over_first": cull.ms / first.ms,
            "two_over_bare": two.ms / bare.ms, "two_culled_over_bare": cull.ms / bare.ms,
            "two_culled_peak_mb": cull_mb, "two_culled_compile_ms": cull.compile_ms,
            "first_layer_ms": first.ms, "first_over_ray_intersect": first.ms / full.ms,
            "two_layer_ms": two.ms, "first_over_bare": first.ms / bare.ms,
            "two_over_first": two.ms / first.ms, "mrays_per_s": R * R / bare.ms / 1e3,
            "first_peak_mb": first_mb, "two_peak_mb": two_mb,
            "first_compile_ms": first.compile_ms, "two_compile_ms": two.compile_ms,
            "kernel_bare_ms": k["bare"], "kernel_first_ms": k["first"], "kernel_two_ms": k["two"],
            "kernel_two_culled_ms": k["cull"]}


def _lookup_rows(sd, label, view, p, n, ext, repeats) -> list:
    """(2) and (3): each scheme's lookup on a 1024^2 two-layer map with slope, against constant bias's."""
    import drjit as dr

    from ..maps import lookup, shadowmap
    from ..maps.receiver import Receiver
    from .. import schemes
    from ..core import timing
    smap = shadowmap.build(sd.scene, view, {"z2", "slope"}, extents=ext)
    rx = Receiver.make(view, p, n, sd.diagonal)
    dr.eval(rx.depth, rx.u_map, rx.v_map, rx.texel_world, rx.to_light)
    rows, base = [], None
    for name in ("constant", "slope_scaled", "adaptive", "dual", "receiver_plane", "normal_offset", "midpoint",
                 "none"):
        mod = schemes.get(name)
        prm = mod.Params() if name != "dual" else mod.Params(culling="none")
        t, mb = _peak(timing, lambda: lookup.visibility(mod, prm, rx, smap), repeats)[1:]
        base = base or t.ms
        rows.append({"scene": label, "scheme": name, "receivers": dr.width(p), "lookup_ms": t.ms,
                     "over_constant": t.ms / base, "compile_ms": t.compile_ms, "peak_mb": mb})
    return rows


def markdown(r) -> str:
    """bench.md: every section measured, in order."""
    from .bench_geometry import markdown as geometry_md
    lines = _md_builds(r) + _md_two(r) + _md_lookups(r) + _md_scaling(r) + _md_frame(r)
    if r.get("complete") is False:      # an interrupted perf: what it measured, said at the top
        lines[1:1] = ["", f"Interrupted: measured only {', '.join(r['sections']) or 'nothing'}."]
    from .bench_prefilter import markdown as prefilter_md
    lines += geometry_md(r["geometry"]) if r.get("geometry") else []
    lines += prefilter_md(r["prefilter"]) if r.get("prefilter") else []
    from .bench_modes import markdown as lookups_md, markdown_builds
    lines += _md_sweep(r) + (lookups_md(r["lookup_modes"]) if r.get("lookup_modes") else [])
    lines += markdown_builds(r["build_modes"]) if r.get("build_modes") else []
    return "\n".join(lines) + "\n"


def versions_line(r) -> str:
    """bench.md's line naming what its times depend on: the versions and the machine."""
    v, m = r["versions"], r.get("machine") or {}
    return (f"dsm {v['dsm']} ({v['dsm_git_commit']}), Mitsuba {v['mitsuba']}, Dr.Jit {v['drjit']}, "
            f"libLLVM {v['libllvm']}, Python {v['python']}; {m.get('cpu', 'unknown CPU')}, "
            f"{m.get('cores', '?')} cores, {m.get('system', 'unknown system')}")


def _md_builds(r) -> list:
    """Section (1): builds against a full and a bare cast, wall clock."""
    lines = [f"# dsm perf ({r['variant']}, {r['threads']} threads, median of {r['repeats']} warm runs; "
             f"(4) and (7): of {max(1, min(r['repeats'], 3))}; (6): of {max(r['repeats'], 5)})", "",
             "## (1) Map build against a bare ray cast of the same texel rays", "",
             "Goals (kernel time, the second table of (1b)): first layer / preliminary <= 1.5, two layers / "
             "preliminary <= 2.5. Peak: Dr.Jit's allocation watermark during the build "
             "(the map itself included). Compile time is reported apart (cold run). Every cast is Embree's "
             "incoherent traversal (a ray's hit does not depend on its packet); *coherent ms* is the same "
             "preliminary cast with the coherent traversal, for its cost.", "",
             "| scene | R | ray_intersect ms | preliminary ms | coherent ms | Mrays/s | first layer ms | "
             "first / ray_intersect | first / preliminary | two layers ms | two / first | first peak MB | two peak MB "
             "| compile ms |",
             "|---" * 14 + "|"]
    lines[1:1] = ["", versions_line(r)] if r.get("versions") else []
    cells = [("ray_intersect_ms", ".2f"), ("bare_ms", ".2f"), ("bare_coherent_ms", ".2f"), ("mrays_per_s", ".1f"),
             ("first_layer_ms", ".2f"), ("first_over_ray_intersect", ".2f"), ("first_over_bare", ".2f"),
             ("two_layer_ms", ".2f"), ("two_over_first", ".2f"), ("first_peak_mb", ".1f"), ("two_peak_mb", ".1f"),
             (lambda b: f"{b['first_compile_ms']:.0f} / {b['two_compile_ms']:.0f}", "")]
    return lines + _build_rows(r["builds"], cells)


def _build_rows(builds, cells) -> list:
    """One markdown row per build: its scene and R, then each cell, a (key, format) or a (function, "")."""
    def cell(b, key, fmt):
        return key(b) if callable(key) else format(b[key], fmt)
    return ["| " + " | ".join([str(b["scene"]), str(b["resolution"])] + [cell(b, k, f) for k, f in cells]) + " |"
            for b in builds]


def _md_two(r) -> list:
    """Section (1b): two layers against the first and a bare cast, wall clock and kernel time."""
    lines = ["", "## (1b) Two layers (z1, z2) against the first layer and a bare preliminary cast", "",
              "Wall clock, back to back (the goals are read in kernel time, below).", "",
              "| scene | R | preliminary ms | first ms | two ms | two / first | two / preliminary | "
              "two culled ms | culled / first | culled / preliminary |", "|---" * 10 + "|"]
    lines += _build_rows(r["builds"], [(k, ".2f") for k in ("bare_ms", "first_layer_ms", "two_layer_ms", "two_over_first",
                                                             "two_over_bare", "two_culled_ms", "two_culled_over_first",
                                                             "two_culled_over_bare")])
    lines += ["", "The same builds as kernel time (each kernel's own execution time from Dr.Jit's kernel "
              "history, summed over the kernels of one build; Python's tracing and launch overhead excluded). "
              "The four are timed interleaved, one call of each in turn per repeat, so a change of the machine's "
              "load falls on all of them. Goals: first / preliminary <= 1.5, two / preliminary <= 2.5.", "",
              "| scene | R | preliminary ms | first ms | first / preliminary | two ms | two / first | "
              "two / preliminary | two culled ms | culled / first |", "|---" * 10 + "|"]
    ratio = lambda num, den: (lambda b: f"{b[num] / b[den]:.2f}", "")
    lines += _build_rows(r["builds"], [("kernel_bare_ms", ".3f"), ("kernel_first_ms", ".3f"),
                                       ratio("kernel_first_ms", "kernel_bare_ms"), ("kernel_two_ms", ".3f"),
                                       ratio("kernel_two_ms", "kernel_first_ms"), ratio("kernel_two_ms", "kernel_bare_ms"),
                                       ("kernel_two_culled_ms", ".3f"), ratio("kernel_two_culled_ms", "kernel_first_ms")])
    return lines


def _lookup_res(r) -> str:
    """The map resolution of sections (2) and (3): 1024, or the nearest the bench was given."""
    res = sorted({x.get("resolution", 1024) for x in r["lookups"]})
    return ", ".join(map(str, res)) or "1024"


def _md_lookups(r) -> list:
    """Sections (2) and (3): lookups per scheme against constant bias, and their peak memory."""
    lines = ["", "Weiskopf & Ertl, Table 1: the dual map's build costs about twice the single map's.", "",
              f"## (2) Lookup time per scheme ({_lookup_res(r)}^2 map, 512^2 camera) as a ratio to constant bias, "
              "and (3) its peak memory", "",
              "| scene | scheme | receivers | lookup ms | / constant | Dou et al. Table 1 / constant | peak MB |",
              "|---|---|---|---|---|---|---|"]
    for x in r["lookups"]:
        dou = r["dou_table1_ms"].get(x["scheme"])
        ref = f"{dou / r['dou_table1_ms']['constant']:.2f}" if dou else ""
        lines.append(f"| {x['scene']} | {x['scheme']} | {x['receivers']} | {x['lookup_ms']:.3f} | "
                     f"{x['over_constant']:.2f} | {ref} | {x['peak_mb']:.1f} |")
    lines += ["", "Dou et al.'s ratios are of whole frames on a GTX 580 (1024^2 map, Sponza); ours are of the "
              "lookup alone, so the map build is in the first table."]
    return lines


def _md_scaling(r) -> list:
    """Section (4): build time against resolution, with the fitted exponents."""
    from .bench_geometry import exponent_text
    lines = []
    if r.get("scaling"):
        lines += ["", f"## (4) Build time against resolution (tiled within the memory budget of "
                  f"{r['budget_mb']:.0f} MB)", "",
                  "| scene | R | texels | first ms | tiles | ns/texel | two layers ms | tiles | ns/texel |",
                  "|---" * 9 + "|"]
        for x in r["scaling"]:
            lines.append(f"| {x['scene']} | {x['resolution']} | {x['texels']} | {x['first_ms']:.1f} | "
                         f"{x['first_tiles']} | {x['ns_per_texel_first']:.1f} | {x['two_ms']:.1f} | "
                         f"{x['two_tiles']} | {x['ns_per_texel_two']:.1f} |")
        lines += ["", "Fitted exponent of time against texels (log-log least squares; 1 is linear):", "",
                  "| scene | first layer | two layers |", "|---|---|---|"]
        for label, e in r["exponents"].items():
            lines.append(f"| {label} | {exponent_text(e['first'])} | {exponent_text(e['two'])} |")
    return lines


def _md_frame(r) -> list:
    """Section (6): one frame's kernel, frozen and wall time."""
    lines = []
    if r.get("frame"):
        f = r["frame"]
        frozen = (f"{f['frozen_ms']:.3f} ms (replays equal to a traced frame: {f['frozen_same']})"
                  if f.get("frozen_ms") is not None else f"not measured ({f.get('frozen_error')})")
        lines += ["", f"## (6) One frame: a {f['map']}^2 map of {f['scene']} and every single-layer scheme's "
                  f"nearest lookup over a {f['camera']}^2 camera ({f['receivers']} visible pixels)", "",
                  f"Schemes: {', '.join(f['schemes'])}.", "",
                  "| measure | ms |", "|---|---|",
                  f"| kernel time (sum of the {f['kernels']} kernels' execution times) | {f['kernel_ms']:.3f} |",
                  f"| frozen frame replayed (dr.freeze; tracing removed) | {frozen} |",
                  f"| wall clock, Python's tracing included | {f['wall_ms']:.3f} |",
                  f"| bare ray_intersect_preliminary of the map's rays, kernel time | {f['bare_kernel_ms']:.3f} |",
                  f"| bare ray_intersect_preliminary, wall clock | {f['bare_wall_ms']:.3f} |",
                  f"| compile (cold frame) | {f['compile_ms']:.0f} |"]
    return lines


def _md_sweep(r) -> list:
    """Section (5): sweep throughput, local against a local Ray cluster."""
    lines = []
    if r.get("sweep"):
        w = r["sweep"]
        lines += ["", "## (5) Sweep throughput: a local run against a local Ray cluster", ""]
        kl = w.get("kernel_launches")
        if kl:
            lines += [f"Kernel launches of the local run (Dr.Jit's kernel history): {kl['outside_repeats']} outside the "
                      f"timed repeats ({kl['outside_per_case']:.2f} a case), {kl['timed_repeats']} inside them.", ""]
        if "ray_s" in w:
            lines += [f"{w['cases']} cases. Local: {w['local_s']:.1f} s ({w['local_cases_per_s']:.2f} cases/s). "
                      f"Ray, {w['workers']} workers: {w['ray_s']:.1f} s ({w['ray_cases_per_s']:.2f} cases/s), "
                      f"{w['speedup']:.2f}x; rows equal count for count: {w['rows_equal']}. Ray's start-up is "
                      "not counted; each Ray task loads its scene, G-buffer and reference again."]
        else:
            lines += [f"{w['cases']} cases locally: {w['local_cases_per_s']:.2f} cases/s; Ray: {w['ray']}."]
    return lines
