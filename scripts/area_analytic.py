"""The analytic square-light scene through the pipeline: a square light (side 1, height 4) above
a square plate (side 1, height 2) over a ground plane, seen by a 256^2 camera. Prints the
reference against the closed-form visible fraction (mean and 99th percentile of |V* - exact| over
the penumbra, the share outside the reported interval, regions against the exact ones, rays per
region), then per scheme and filter the MAE by region and acne / peter-panning.

    PYTHONPATH=.:plugins .venv/bin/python scripts/area_analytic.py [--light rectangle|emitter] [--seed N]
"""
import argparse
import tempfile
from pathlib import Path

import mitsuba as mi
import numpy as np

from dsm.core import env

env.use_variant("llvm_ad_rgb")
import dsm.pipeline as pl                                   # noqa: E402
from dsm.scenes import camera as scene_camera, geometry as scene_geometry
from dsm.core.types import LightSpec

A, H, B, HS = 1.0, 4.0, 1.0, 2.0
W = 256


def quad(z, half):
    """A square at height z, wound upward."""
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    return scene_geometry.make_mesh("quad", v, np.array([[0, 1, 2], [0, 2, 3]]))


def luminaire(z, half, folder):
    """The light as the XML's own kind: an area emitter on a PLY square wound downward."""
    path = Path(folder) / "luminaire.ply"
    v = [(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)]
    path.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                    + "".join(f"{x} {y} {zz}\n" for x, y, zz in v) + "3 0 2 1\n3 0 3 2\n")
    return {"type": "ply", "filename": str(path), "emitter": {"type": "area"}}


def analytic(q):
    """Closed-form V from ground points q (n, 2): the plate projects from q onto the light's plane
    as a square of side B H / Hs centred at q (1 - H / Hs); V = 1 - overlap / A^2."""
    c, s = q * (1 - H / HS), B * H / HS
    ov = [np.clip(np.minimum(c[:, k] + s / 2, A / 2) - np.maximum(c[:, k] - s / 2, -A / 2), 0, None) for k in (0, 1)]
    return 1 - ov[0] * ov[1] / A ** 2


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--light", default="rectangle", choices=("rectangle", "emitter"))
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    parts = {"type": "scene", "ground": quad(0.0, 6.0), "occluder": quad(HS, B / 2),
             "sensor": scene_camera.look_at_sensor((0.0, -7.0, 6.0), (0, 0, 0), (0, 0, 1), 45, W, W)}
    if args.light == "emitter":
        parts["luminaire"] = luminaire(H, A / 2, tempfile.mkdtemp())
    sd = pl.scene_from_mitsuba(mi.load_dict(parts), "analytic_square")
    gb = pl.gbuffer(sd)
    if args.light == "emitter":
        light = pl.area_emitter_lights(sd.scene, LightSpec("area", shape="emitter"))[0]
    else:
        light = LightSpec("area", position=(0.0, 0.0, H), direction=(0.0, 0.0, -1.0), shape="rectangle",
                          size=(A,), label="area")
    setup = pl.light_setup(sd, gb, light, "0:area", seed=args.seed)
    p = pl.points_np(setup.p)
    ground = np.abs(p[:, 2]) < 1e-4
    vt, ref = analytic(p[ground, :2]), setup.ref
    v, pen = setup.v_frac[ground], (vt > 0) & (vt < 1)
    err = np.abs(v - vt)
    print(f"{args.light}: ground receivers {ground.sum()}, penumbra mean |V*-exact| {err[pen].mean():.4f}, "
          f"p99 {np.percentile(err[pen], 99):.4f}, max {err.max():.4f}")
    if hasattr(ref, "low"):
        out = (vt < ref.low[ground]) | (vt > ref.high[ground])
        print(f"  outside the {ref.confidence:g} interval: {out.mean():.4f}")
    hits, samples = ref.hits[ground], ref.samples[ground]
    print(f"  regions umbra/penumbra/lit: {(hits == 0).sum()}/{((hits > 0) & (hits < samples)).sum()}/"
          f"{(hits == samples).sum()}; exact {(vt <= 0).sum()}/{pen.sum()}/{(vt >= 1).sum()}")
    st = ref.stats()
    print("  rays per receiver umbra/penumbra/lit: " + "/".join(
        f"{st[k]['rays_per_receiver']:.0f}" for k in ("umbra", "penumbra", "lit")) + f", rays {st['rays']:,}, "
          f"reference {setup.reference_ms:.0f} ms")


if __name__ == "__main__":
    main()
