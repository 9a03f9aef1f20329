"""The origin rules' own acne and leaking across scene scales (docs/hybrid.md, *Where a ray starts*).

Two built-ins under their own directional light at each scale (:data:`SCENES`): the box on the
ground (``plane_box``: a contact, where an origin pushed too far leaks) and a plane tilted off
every axis (``plane`` 60 degrees at azimuth 30: its hit points carry rounding in every
coordinate, where an origin too close re-hits the plane; the box's faces and ground are
axis-aligned and round to themselves). One shadow ray per receiver under each origin rule
(:mod:`dsm.hybrid.origins`) against a float64 truth: the ray from the float32 hit point toward the
light against the other shapes' triangles (a receiver's own shape cannot shade it here: planes
and a convex box, its receivers facing the light), so no offset enters the truth. False shadow: the rule's ray hits where the truth is lit
(self-intersection); leak: it misses where the truth is shadowed (an origin pushed past the box).
"""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import SceneSpec
from ..scenes import gbuffer, load, spec as scene_spec
from ..truth import reference
from .origins import ORIGINS, rays

SCALES = (1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6)
SCENES = (("plane_box", {}), ("plane", {"tilt": 60.0, "azimuth": 30.0}))
COLUMNS = ("scene", "scale", "origin", "n_receivers", "n_gt_lit", "n_gt_shadowed", "n_false_shadow", "n_leak",
           "false_shadow_rate", "leak_rate")


def _triangles(scene) -> list:
    """Per shape of ``scene``: its triangles as (T, 3, 3) float64 (world)."""
    out = []
    for shape in scene.shapes():
        v = np.asarray(shape.vertex_positions_buffer(), np.float64).reshape(-1, 3)
        f = np.asarray(shape.faces_buffer(), np.int64).reshape(-1, 3)
        out.append(v[f])
    return out


def _blocked(p: np.ndarray, d: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Per ray (float64, Moller-Trumbore): whether it meets one of ``tris`` at t > 0."""
    hit = np.zeros(len(p), bool)
    for a, b, c in tris:
        e1, e2 = b - a, c - a
        h = np.cross(d, e2)
        det = h @ e1
        s = p - a
        u = np.einsum("ij,ij->i", s, h) / det
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", q, d) / det
        t = (q @ e2) / det
        hit |= (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return hit


def truth(sd, si, shape: np.ndarray, light) -> np.ndarray:
    """V* per receiver in float64, each receiver's own shape left out (shape identity is surface
    identity here: SCENES are a plane and a convex box on the ground, each surface its own shape
    and none able to shade itself; a merged mesh would need a per-triangle rule)."""
    p = np.stack([np.asarray(c.numpy(), np.float64) for c in si.p], 1)
    to_light = -np.asarray(light.direction, np.float64) / np.linalg.norm(light.direction)
    d = np.broadcast_to(to_light, p.shape).copy()
    shadowed = np.zeros(len(p), bool)
    for k, tris in enumerate(_triangles(sd.scene)):
        others = shape != k
        shadowed[others] |= _blocked(p[others], d[others], tris)
    return ~shadowed


def one_scale(builtin: str, params: dict, scale: float, resolution: int = 128) -> list:
    """COLUMNS rows of every origin rule at one scale of a built-in under its own light."""
    table = {"builtin": builtin, **params, "scale": scale}
    spec: SceneSpec = scene_spec.parse_scene(table, "<origins>", "scene", Path("."))[0]
    sd = load.load(spec, (resolution, resolution))
    assert sd.centre is None           # scaled about the origin: traced in world coordinates
    light = sd.own_lights[0]
    gb = gbuffer.cast(sd.scene, sd.sensor, resolution, resolution)
    to_light = -np.asarray(light.direction, np.float64) / np.linalg.norm(light.direction)
    n = np.stack([np.asarray(c.numpy(), np.float64) for c in gb.n], 1)
    keep = np.flatnonzero(gb.hit & (n @ to_light > 0)).astype(np.uint32)
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, mi.UInt32(keep))
    v_star = truth(sd, si, gb.shape.numpy()[keep], light)
    magnitude = reference.scene_magnitude(sd.bbox)
    rows = []
    for origin in ORIGINS:
        lit = ~sd.scene.ray_intersect_preliminary(rays(si, light, magnitude, origin), coherent=False).is_valid()
        lit = lit.numpy().astype(bool)
        fs, leak = int(np.count_nonzero(v_star & ~lit)), int(np.count_nonzero(~v_star & lit))
        n_lit, n_sh = int(v_star.sum()), int((~v_star).sum())
        rows.append({"scene": builtin, "scale": scale, "origin": origin, "n_receivers": len(keep), "n_gt_lit": n_lit,
                     "n_gt_shadowed": n_sh, "n_false_shadow": fs, "n_leak": leak,
                     "false_shadow_rate": fs / n_lit if n_lit else float("nan"),
                     "leak_rate": leak / n_sh if n_sh else float("nan")})
    return rows


def table(scales=SCALES, resolution: int = 128, scenes=SCENES) -> list:
    """COLUMNS rows of every origin rule at every scale of every scene."""
    return [r for b, p in scenes for s in scales for r in one_scale(b, p, s, resolution)]


def markdown(rows: list) -> list:
    """The table's lines: per scale, each rule's false shadow and leak (counts, rates)."""
    origins = list(dict.fromkeys(r["origin"] for r in rows))
    head = "| scene | scale | receivers (lit / shadowed) | " + " | ".join(f"{o}: false shadow / leak" for o in origins) + " |"
    lines = [head, "|---" * (3 + len(origins)) + "|"]
    for scene, s in dict.fromkeys((r["scene"], r["scale"]) for r in rows):
        rs = {r["origin"]: r for r in rows if (r["scene"], r["scale"]) == (scene, s)}
        first = next(iter(rs.values()))
        cells = [f"{rs[o]['n_false_shadow']} / {rs[o]['n_leak']}" for o in origins]
        lines.append(f"| {scene} | {s:g} | {first['n_gt_lit']} / {first['n_gt_shadowed']} | " + " | ".join(cells) + " |")
    return lines
