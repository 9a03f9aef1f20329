"""What makes a scene unusable, as a ConfigError naming the config file and its [[scene]] key."""
from __future__ import annotations

import numpy as np

from ..core.types import ConfigError
from .geometry import CROSS_MAX, CROSS_MIN, cross_lengths


def source_of(spec) -> str:
    """The config file a scene spec came from, for its errors."""
    return spec.source or "<scene>"


def check_held(size: float, offset, source: str, key: str, where_from: str, what: str = "the offset"):
    """ConfigError naming ``key`` where float32 holds fewer than 64 steps across a scene ``size``
    across at ``offset`` (world units): its geometry would round to a few points (degenerate)."""
    t = float(np.max(np.abs(np.asarray(offset, float))))
    if t == 0:
        return
    with np.errstate(over="ignore"):
        step = float(np.spacing(np.float32(t)))      # float32's step at the scene's position
    if not step * 64 <= size:                      # 64 steps across: the scene's shape still held
        raise ConfigError(source, key, f"{t:g} {where_from} float32 moves in steps of {step:.3g}, and the scene "
                          f"is {size:.3g} across: its geometry cannot be held there (keep {what} below "
                          f"{size / 64 * 2 ** 23:.3g})")


def check_mesh(shape, name: str, spec):
    """ConfigError naming the [[scene]] key where a mesh has no triangles, non-finite positions,
    faces beyond its vertices or triangles whose float32 normals overflow or underflow."""
    src = source_of(spec)
    key = f"{spec.where}.builtin" if spec.builtin else f"{spec.where}.file"
    size_key = f"{spec.where}.scale" if spec.params is not None and getattr(spec.params, "scale", 1.0) != 1.0 else key
    what = spec.builtin or str(spec.file)
    # the buffers, not mi.traverse: a rectangle or disk mesh exposes only its to_world there
    v = np.array(shape.vertex_positions_buffer(), np.float64).reshape(-1, 3)
    f = np.array(shape.faces_buffer(), np.int64).reshape(-1, 3)
    if len(f) == 0:
        raise ConfigError(src, key, f"{what}: shape {name!r} has no triangles")
    if not np.isfinite(v).all():
        bad = int((~np.isfinite(v).all(1)).sum())
        raise ConfigError(src, key, f"{what}: shape {name!r} has {bad} vertex positions that are not finite "
                          "(NaN or inf)")
    if f.max() >= len(v):
        raise ConfigError(src, key, f"{what}: shape {name!r} has faces referring to vertex {int(f.max())} "
                          f"of {len(v)}")
    c = cross_lengths(v, f)
    if c.max() > CROSS_MAX:
        raise ConfigError(src, size_key, f"{what}: shape {name!r} has {int((c > CROSS_MAX).sum())} triangles too "
                          f"large for Mitsuba's float32 normals (|e1 x e2| up to {c.max():.2g}, limit "
                          f"{CROSS_MAX:g}): scale the scene down")
    nz = c[c > 0]
    if nz.size == 0:
        raise ConfigError(src, key, f"{what}: shape {name!r} has only degenerate (zero-area) triangles")
    if (nz < CROSS_MIN).mean() > 0.01:
        raise ConfigError(src, size_key, f"{what}: shape {name!r} has triangles too small for Mitsuba's float32 "
                          f"normals (|e1 x e2| down to {nz.min():.2g}, limit {CROSS_MIN:g}): scale the scene up")


def check_loaded(spec, data):
    """What a loaded scene must hold: shapes, triangles, finite positions, float32-safe normals."""
    src = source_of(spec)
    key = f"{spec.where}.builtin" if spec.builtin else f"{spec.where}.file"
    what = spec.builtin or str(spec.file)
    shapes = list(data.scene.shapes())
    if not shapes:
        raise ConfigError(src, key, f"{what} has no shapes")
    for name, shape in zip(data.shape_names, shapes):
        if shape.is_mesh() and name not in data.checked:
            check_mesh(shape, name, spec)
    if not (np.isfinite(data.bbox[0]).all() and np.isfinite(data.bbox[1]).all()):
        raise ConfigError(src, key, f"{what}: its bounding box is not finite")
    unknown = [n for n, _ in spec.closed if n not in data.shape_names]
    if unknown:
        raise ConfigError(src, f"{spec.where}.closed.{unknown[0]}", f"no shape named {unknown[0]!r} in {what}",
                          data.shape_names, got=unknown[0])


def check_options(cfg, spec, sd):
    """ConfigError where a loaded scene cannot take the config's opt-in steps: contact shadows and
    distance-scaled schemes need a perspective camera, caster shrinking triangle meshes."""
    import mitsuba as mi
    need = ["contact"] if getattr(cfg, "contact", None) is not None else []
    need += [f"scheme {s.name}" for s in cfg.schemes if s.name == "distance_normal"][:1]
    if need and "x_fov" not in mi.traverse(sd.sensor):
        raise ConfigError(source_of(spec), need[0].split()[0], f"{spec.where}: {need[0]} needs a perspective camera; the "
                          f"scene's sensor has no field of view ({type(sd.sensor).__name__})")
    if getattr(cfg, "shrink", None) is not None:
        flat = [sh.id() or str(i) for i, sh in enumerate(sd.scene.shapes()) if not sh.is_mesh()]
        if flat:
            raise ConfigError(source_of(spec), "map.shrink", f"{spec.where}: shrinking moves mesh vertices and "
                              + (f"{flat[0]} is not a triangle mesh; remove map.shrink or give it as a mesh"
                                 if len(flat) == 1 else f"{', '.join(flat[:3])} are not triangle meshes; remove "
                                 "map.shrink or give them as meshes"))
        check_shrink_fits(cfg.shrink, spec, sd)


def check_shrink_fits(d: float, spec, sd):
    """ConfigError where ``[map] shrink`` is at least half the thinnest box extent of a closed mesh:
    its copy moved ``d`` inward passes through itself and comes out inside out (a caster larger
    than the shape, facing in)."""
    from .closedness import shape_closedness
    for i, (name, shape) in enumerate(zip(sd.shape_names, sd.scene.shapes())):
        closed, why = shape_closedness(shape)
        if not closed or "wound inward" in why:        # open shapes and rooms move, they do not invert
            continue
        bb = shape.bbox()
        thin = float(np.min(np.array(bb.max, float).ravel() - np.array(bb.min, float).ravel()))
        if d >= thin / 2:
            raise ConfigError(source_of(spec), "map.shrink", f"{spec.where}: {d:g} is at least half the thinnest extent "
                              f"of the closed shape {name!r} ({thin:.3g} across): moved that far inward it turns "
                              f"inside out; give less than {thin / 2:.3g}")
