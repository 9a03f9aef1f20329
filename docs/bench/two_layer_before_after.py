"""Before/after in one process, round-robin, min of N: old (main's) shadowmap vs this branch's."""
import sys, time, json, importlib.util
from pathlib import Path
import numpy as np
from dsm import env; env.use_variant("llvm_ad_rgb")
import drjit as dr, mitsuba as mi
from dsm import shadowmap, spawn, pipeline
from dsm.scenes import load as scenes
from dsm.config import SceneSpec, LightSpec
from dsm.scenes import FileParams, PlaneBoxParams
spec = importlib.util.spec_from_file_location("oldsm", "/tmp/scale_old_shadowmap.py"); old = importlib.util.module_from_spec(spec); sys.modules["oldsm"] = old; spec.loader.exec_module(old)
M = Path(__file__).resolve().parents[2] / "data" / "meshes"; N = int(sys.argv[1])
specs = [SceneSpec(builtin="plane_box", params=PlaneBoxParams(), label="plane_box"),
         SceneSpec(file=M/"mitsuba_bunny.ply", params=FileParams(up="y"), label="mitsuba_bunny"),
         SceneSpec(file=M/"sponza_dabrovic.ply", params=FileParams(up="y"), label="sponza_dabrovic")]
def once(fn):
    dr.sync_thread(); t0 = time.perf_counter(); r = fn(); dr.eval(*[x for x in r if x is not None and hasattr(x, "index")]); dr.sync_thread(); return 1e3 * (time.perf_counter() - t0)
out = []
for sp in specs:
    sd = scenes.load(sp, (512, 512)); ext = spawn.shape_extents(sd.scene)
    from dsm.gbuffer import cast
    gb = cast(sd.scene, sd.sensor, 512, 512)
    pix = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    pts = pipeline.points_np(dr.gather(mi.Point3f, gb.p, pix))
    lt = LightSpec("directional", direction=(-0.4, -0.3, -1.0)) if sp.builtin else LightSpec("directional", direction=(0.25, -1.0, 0.15))
    cull = pipeline.cull_modes("back_closed", pipeline.closedness(sd)[0])
    for R in (1024, 2048):
        view = pipeline.make_view(lt, R, pts, sd.bbox)
        rays = view.texel_rays(0, R * R); dr.eval(rays)
        fns = {"bare": lambda: (sd.scene.ray_intersect_preliminary(rays, coherent=True).t,),
               "first_before": lambda: old.arrays(old.build(sd.scene, view, set(), extents=ext)),
               "first_after": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, set(), extents=ext)),
               "two_before": lambda: old.arrays(old.build(sd.scene, view, {"z2"}, extents=ext)),
               "two_after": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, extents=ext)),
               "culled_before": lambda: old.arrays(old.build(sd.scene, view, {"z2"}, "back_closed", cull, extents=ext)),
               "culled_after": lambda: shadowmap.arrays(shadowmap.build(sd.scene, view, {"z2"}, "back_closed", cull, extents=ext))}
        for f in fns.values(): once(f)       # warm-up (compile)
        ts = {k: [] for k in fns}
        for _ in range(N):
            for k, f in fns.items(): ts[k].append(once(f))
        m = {k: min(v) for k, v in ts.items()}
        row = {"scene": sp.label, "R": R, **{k: round(v, 1) for k, v in m.items()}}
        out.append(row); print(json.dumps(row), flush=True)
json.dump(out, open(sys.argv[2], "w"), indent=1)
