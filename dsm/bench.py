"""``dsm bench``: what a map build and a lookup cost, as ratios measured in one run.

(1) Map build time (first layer; two layers for dual) over the time of a bare
``scene.ray_intersect`` of the same texel rays (and of the cheaper
``ray_intersect_preliminary`` the build itself uses), per resolution and scene.
(2) Lookup time of each scheme over constant bias's, beside Dou et al.'s Table 1.
(3) Peak memory of each build and lookup (Dr.Jit's allocation watermark).
Warm medians after a JIT warm-up; ``dr.sync_thread()`` around every clock read.
A benchmark, not a test: results go to bench.md and bench.json.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

DOU_TABLE1 = {"constant": 6.327, "slope_scaled": 6.647, "adaptive": 7.319, "dual": 9.890}


def _scenes(meshes: Path):
    from .config import SceneSpec
    from .scenes import FileParams, PlaneBoxParams
    out = [SceneSpec(builtin="plane_box", params=PlaneBoxParams(), label="plane_box")]
    for name, up in (("mitsuba_bunny.ply", "y"), ("sponza_dabrovic.ply", "y")):
        if (meshes / name).is_file():
            out.append(SceneSpec(file=meshes / name, params=FileParams(up=up), label=Path(name).stem))
    return out


def _peak(timing, fn, repeats):
    """(None, Timing, peak MB above what was allocated before): outputs are dropped."""
    timing.reset_peak()
    before = timing.peak_bytes()
    _, t = timing.measure(fn, repeats)
    return None, t, (timing.peak_bytes() - before) / 2 ** 20


def run_bench(out: Path, resolutions=(256, 512, 1024, 2048, 4096), repeats: int = 5, meshes: Path | None = None,
              variant: str | None = None) -> dict:
    import drjit as dr
    import mitsuba as mi

    from . import env, lookup, scenes, schemes, shadowmap, spawn, timing
    from .config import LightSpec
    from .pipeline import closedness, cull_modes, make_view, points_np as _points_np
    from .gbuffer import cast

    variant = env.use_variant(variant)
    timing.enable_history()
    meshes = Path(meshes) if meshes else Path(__file__).resolve().parents[2] / "shared" / "meshes"
    light = LightSpec("directional", direction=(0.25, -1.0, 0.15))
    builds, lookups = [], []
    for spec in _scenes(meshes):
        sd = scenes.load(spec, (512, 512))
        lt = LightSpec("directional", direction=(-0.4, -0.3, -1.0)) if spec.builtin else light
        gb = cast(sd.scene, sd.sensor, 512, 512)
        pix = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
        ext = spawn.shape_extents(sd.scene)          # once per scene, outside the timed builds
        per_shape = cull_modes("back_closed", closedness(sd)[0])   # dual's default: culls closed meshes only
        p, n = dr.gather(mi.Point3f, gb.p, pix), dr.gather(mi.Vector3f, gb.n, pix)
        for R in resolutions:
            view = make_view(lt, R, _points_np(p), sd.bbox)
            rays = view.texel_rays(0, R * R)
            dr.eval(rays)
            def full_cast():
                si = sd.scene.ray_intersect(rays, mi.RayFlags.All, True)
                return si.t, si.p, si.n
            full = timing.measure(full_cast, repeats)[1]
            bare = timing.measure(lambda: (sd.scene.ray_intersect_preliminary(rays, coherent=True).t,), repeats)[1]
            del rays
            first, first_mb = _peak(timing, lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, set(), extents=ext)),
                                    repeats)[1:]
            two, two_mb = _peak(timing, lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, extents=ext)),
                                repeats)[1:]
            cull, cull_mb = _peak(timing, lambda: shadowmap.arrays(shadowmap.build(
                sd.scene, view, {"z2"}, "back_closed", per_shape, extents=ext)), repeats)[1:]
            builds.append({"scene": spec.label, "resolution": R, "ray_intersect_ms": full.ms, "bare_ms": bare.ms,
                           "two_culled_ms": cull.ms, "two_culled_over_first": cull.ms / first.ms,
                           "two_over_bare": two.ms / bare.ms, "two_culled_over_bare": cull.ms / bare.ms,
                           "two_culled_peak_mb": cull_mb, "two_culled_compile_ms": cull.compile_ms,
                           "first_layer_ms": first.ms, "first_over_ray_intersect": first.ms / full.ms,
                           "two_layer_ms": two.ms, "first_over_bare": first.ms / bare.ms,
                           "two_over_first": two.ms / first.ms, "mrays_per_s": R * R / bare.ms / 1e3,
                           "first_peak_mb": first_mb, "two_peak_mb": two_mb,
                           "first_compile_ms": first.compile_ms, "two_compile_ms": two.compile_ms})
            if R == 1024:
                smap = shadowmap.build(sd.scene, view, {"z2", "slope"}, extents=ext)
                rx = lookup.Receiver.make(view, p, n, sd.diagonal)
                dr.eval(rx.depth, rx.u_map, rx.v_map, rx.texel_world, rx.to_light)
                base = None
                for name in ("constant", "slope_scaled", "adaptive", "dual", "receiver_plane", "normal_offset",
                             "midpoint", "none"):
                    mod = schemes.get(name)
                    prm = mod.Params() if name != "dual" else mod.Params(culling="none")
                    t, mb = _peak(timing, lambda: lookup.visibility(mod, prm, rx, smap), repeats)[1:]
                    base = base or t.ms
                    lookups.append({"scene": spec.label, "scheme": name, "receivers": dr.width(p),
                                    "lookup_ms": t.ms, "over_constant": t.ms / base,
                                    "compile_ms": t.compile_ms, "peak_mb": mb})
    result = {"variant": variant, "threads": dr.thread_count(), "repeats": repeats, "builds": builds,
              "lookups": lookups, "dou_table1_ms": DOU_TABLE1}
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(result, indent=2))
    (out / "bench.md").write_text(_markdown(result))
    return result


def _markdown(r) -> str:
    lines = [f"# dsm bench ({r['variant']}, {r['threads']} threads, median of {r['repeats']} warm runs)", "",
             "## (1) Map build against a bare ray cast of the same texel rays", "",
             "Goal: first layer / ray_intersect <= 1.2. Peak: Dr.Jit's allocation watermark during the build "
             "(the map itself included). Compile time is reported apart (cold run).", "",
             "| scene | R | ray_intersect ms | preliminary ms | Mrays/s | first layer ms | first / ray_intersect | "
             "first / preliminary | two layers ms | two / first | first peak MB | two peak MB | compile ms |",
             "|---" * 13 + "|"]
    for b in r["builds"]:
        lines.append(f"| {b['scene']} | {b['resolution']} | {b['ray_intersect_ms']:.2f} | {b['bare_ms']:.2f} | "
                     f"{b['mrays_per_s']:.1f} | {b['first_layer_ms']:.2f} | {b['first_over_ray_intersect']:.2f} | "
                     f"{b['first_over_bare']:.2f} | {b['two_layer_ms']:.2f} | {b['two_over_first']:.2f} | "
                     f"{b['first_peak_mb']:.1f} | {b['two_peak_mb']:.1f} | "
                     f"{b['first_compile_ms']:.0f} / {b['two_compile_ms']:.0f} |")
    lines += ["", "## (1b) Two layers (z1, z2) against the first layer and a bare preliminary cast", "",
              "Goals: two / first <= 2.0 without culling, <= 2.5 with per-shape culling (back_closed, dual's "
              "default); two layers / preliminary <= 2.2.", "",
              "| scene | R | preliminary ms | first ms | two ms | two / first | two / preliminary | "
              "two culled ms | culled / first | culled / preliminary |", "|---" * 10 + "|"]
    for b in r["builds"]:
        lines.append(f"| {b['scene']} | {b['resolution']} | {b['bare_ms']:.2f} | {b['first_layer_ms']:.2f} | "
                     f"{b['two_layer_ms']:.2f} | {b['two_over_first']:.2f} | {b['two_over_bare']:.2f} | "
                     f"{b['two_culled_ms']:.2f} | {b['two_culled_over_first']:.2f} | "
                     f"{b['two_culled_over_bare']:.2f} |")
    lines += ["", "Weiskopf & Ertl, Table 1: the dual map's build costs about twice the single map's.", "",
              "## (2) Lookup time per scheme (1024^2 map, 512^2 camera) as a ratio to constant bias, "
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
    return "\n".join(lines) + "\n"
