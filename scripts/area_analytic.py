"""The analytic square-light scene through the pipeline: a square light (side 1, height 2) above
a square occluder (side 1, height 1) over a ground plane, seen by a 192^2 camera. Prints the
reference against the analytic visible fraction, its rays by region, and per scheme and filter
the MAE by region, RMSE, acne / peter-panning and the lookup time (warm median of 5).

    PYTHONPATH=.:plugins .venv/bin/python scripts/area_analytic.py
"""
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_rgb")
import dsm.pipeline as pl
from dsm import scenes, timing
from dsm.types import LightSpec
A, H, B, HS = 1.0, 2.0, 1.0, 1.0
def quad(z, half):
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    return scenes.make_mesh("quad", v, np.array([[0, 1, 2], [0, 2, 3]]))
W = 192
scene = mi.load_dict({"type": "scene", "ground": quad(0.0, 4.0), "occluder": quad(HS, B / 2),
                      "sensor": scenes.look_at_sensor((0.0, -5.0, 4.0), (0, 0, 0), (0, 0, 1), 45, W, W)})
sd = pl.scene_from_mitsuba(scene, "analytic_square")
gb = pl.gbuffer(sd)
light = LightSpec("area", position=(0.0, 0.0, H), direction=(0.0, 0.0, -1.0), shape="rectangle", size=(A,), label="area")
setup = pl.light_setup(sd, gb, light, "0:area")
p = pl.points_np(setup.p)
ground = np.abs(p[:, 2]) < 1e-4
q = p[ground, :2]
c, s = q * (1 - H / HS), B * H / HS
ov = [np.clip(np.minimum(c[:, k] + s / 2, A / 2) - np.maximum(c[:, k] - s / 2, -A / 2), 0, None) for k in (0, 1)]
vt = 1 - ov[0] * ov[1] / A ** 2
from dsm import area
lo, hi = area.interval(setup.ref.hits[ground], setup.ref.samples[ground], 0.99)
print(f"ground receivers {ground.sum()}, within 99% interval {((vt >= lo) & (vt <= hi)).mean():.4f}, mean |V*-analytic| {np.abs(setup.v_frac[ground]-vt).mean():.4f}")
print("reference", setup.ref.stats())
view = pl.make_view(light, 1024, p, sd.bbox, "fitted")
smap = pl.store(pl.build_map(sd.scene, view), "float32")
rx = pl.receivers(smap.view, setup, sd.diagonal)
print("view", view.kind)
for scheme in ({"name": "constant", "bias": "1.5 texel"}, {"name": "adaptive"}, {"name": "adaptive_tap"}):
    spec = pl.scheme_spec(scheme)
    for filt in ("nearest", "pcf_bilinear", "pcf_jitter4x4", "pcf_wide:7", "pcss"):
        (v, tap), t = timing.measure(lambda: pl.visibility(spec, rx, smap, filt), 5)
        m = pl.metrics(v.numpy(), setup, tap.numpy())
        print(f"{spec.name:13s} {filt:14s} U{m['mae_umbra']:.3f} P{m['mae_penumbra']:.3f} L{m['mae_lit']:.3f} rmse {m['rmse']:.3f} acne {m['acne_rate']:.4f} pp {m['peterpan_rate']:.4f} lookup {t.ms:.2f} ms (compile {t.compile_ms:.0f}) n={m['n_umbra']}/{m['n_penumbra']}/{m['n_lit']}")
