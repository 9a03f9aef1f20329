"""A Mitsuba scene's emitters as LightSpecs, and the default light of a scene without one."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..core.types import ConfigError, LightSpec
from .checks import source_of
from .geometry import normalize


def check_emitters(spec, lights):
    """ConfigError naming the file for an emitter at a position, along a direction or with a
    cutoff that is not finite (every receiver read as backfacing: the case came out empty)."""
    for i, light in enumerate(lights):
        vals = {"position": light.position, "direction": light.direction,
                "cutoff_angle": (light.cutoff,)}        # a spot's; the others keep the finite default
        for name, v in vals.items():
            if v is not None and not all(math.isfinite(c) for c in v):
                raise ConfigError(source_of(spec), f"{spec.where}.file", f"{spec.file}: emitter {i} ({light.type}) has a "
                                  f"{name} that is not finite ({', '.join(f'{c:g}' for c in v)})")


def lights_of(scene) -> tuple[list, list]:
    """(LightSpecs of the scene's point, spot and directional emitters, notes on the others)."""
    lights, notes = [], []
    for e in scene.emitters():
        light = emitter_to_light(e)
        if light is None:
            notes.append(f"emitter {type(e).__name__} ignored (not a point, spot or directional light)")
        else:
            lights.append(light)
    return lights, notes


def _shape_normal(shape):
    """The normal of a shape at its sample (0.5, 0.5): the side an area light emits to; None if unusable."""
    import mitsuba as mi
    try:
        ps = shape.sample_position(0.0, mi.Point2f(0.5, 0.5))
        return normalize(np.array([ps.n.x, ps.n.y, ps.n.z], float).ravel()[:3])
    except Exception:
        return None


def describe_light(light: LightSpec) -> str:
    """One readable line for a light: its type, position and direction (3 significant digits)."""
    vec = lambda v: "(" + ", ".join(f"{c:.3g}" for c in v) + ")"
    parts = [f"{light.type} light"]
    if light.position is not None:
        parts.append(f"at {vec(light.position)}")
    if light.direction is not None:
        parts.append(f"{'shining along' if light.position is None else 'axis'} {vec(light.direction)}")
    return " ".join(parts)


def default_light(scene) -> LightSpec:
    """A light for a scene without a point, spot or directional emitter: a point light at its
    first area light (moved 2 % of the way to the scene's centre, off the luminaire's surface,
    its axis toward the centre), or else a directional light from above (the sensor's up) and a
    little to the side. A luminaire at the scene's centre gets its surface normal as the axis
    (or -z) and sits 0.1 % of the scene's diagonal off its surface: never a NaN direction."""
    import mitsuba as mi
    bb = scene.bbox()
    lo, hi = np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel()
    centre, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    for e in scene.emitters():
        shape = e.get_shape()
        if shape is not None:
            c = np.array(shape.bbox().center(), float).ravel()
            off = centre - c
            if np.linalg.norm(off) > 1e-6 * diag:
                pos, axis = c + 0.02 * off, normalize(off)
            else:
                axis = _shape_normal(shape) or (0.0, 0.0, -1.0)
                pos = c + 1e-3 * max(diag, 1e-30) * np.asarray(axis)
            return LightSpec("point", position=tuple(float(x) for x in pos), direction=axis, label="point")
    up = np.array([0.0, 0.0, 1.0])
    if scene.sensors():
        up = np.array(scene.sensors()[0].world_transform() @ mi.Vector3f(0, 1, 0), float).ravel()
    side = np.cross(up, [0.3, 0.5, 0.8])
    return LightSpec("directional", direction=normalize(-up + 0.3 * side / max(np.linalg.norm(side), 1e-9)),
                     label="directional")


def emitter_to_light(e):
    """A Mitsuba emitter as a LightSpec, or None for kinds the kit does not map (area, env)."""
    import mitsuba as mi
    kind = type(e).__name__.lower()
    text = str(e).lower()
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaDirection):
        d = np.array(e.world_transform() @ mi.Vector3f(0, 0, 1), float).ravel()
        return LightSpec("directional", direction=normalize(d), label="directional")
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition) and ("spot" in kind or "spot" in text):
        tf = e.world_transform()
        pos = np.array(tf @ mi.Point3f(0, 0, 0), float).ravel()
        axis = np.array(tf @ mi.Vector3f(0, 0, 1), float).ravel()
        params = mi.traverse(e)
        cutoff = float(params["cutoff_angle"][0]) if "cutoff_angle" in params else 20.0
        return LightSpec("spot", position=tuple(float(c) for c in pos), direction=normalize(axis), cutoff=cutoff, label="spot")
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition) and "point" in kind + text:
        params = mi.traverse(e)     # a point light keeps its position as a parameter, not in to_world
        pos = (np.array(params["position"], float).ravel() if "position" in params
               else np.array(e.world_transform() @ mi.Point3f(0, 0, 0), float).ravel())
        return LightSpec("point", position=tuple(float(c) for c in pos), direction=(0.0, 0.0, -1.0), label="point")
    return None


def emitter_lights(scene, spec) -> list:
    """One LightSpec per area emitter of ``scene`` (a mesh carrying an area emitter): centre
    (the area-weighted centroid), normal (the area-weighted winding normal), size (the square
    root of its area) and its shape index, which its map excludes. ``spec``: the config's
    ``shape = "emitter"`` light, whose sampling settings they keep."""
    out = []
    for i, shape in enumerate(scene.shapes()):
        if not (shape.is_mesh() and shape.is_emitter()):
            continue
        tri = mesh_triangles(shape)
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        total = float(area.sum())
        if not total > 0:
            continue
        centre = (tri.mean(axis=1) * area[:, None]).sum(0) / total
        normal = normalize(cross.sum(0)) if np.linalg.norm(cross.sum(0)) > 0 else np.array([0.0, 0.0, -1.0])
        out.append(replace(spec, position=tuple(map(float, centre)), direction=tuple(map(float, normal)),
                           size=(math.sqrt(total),), emitter_shapes=(i,), label="area"))
    return out


def mesh_triangles(shape) -> np.ndarray:
    """A mesh's triangles as (n, 3, 3) world positions, float64."""
    v = np.asarray(shape.vertex_positions_buffer(), np.float64).reshape(-1, 3)
    f = np.asarray(shape.faces_buffer(), np.int64).reshape(-1, 3)
    return v[f]
