"""Loading scenes: the entry points (load, check, from_mitsuba) over built-ins, XML and mesh files.

Every built-in is made of triangle meshes in code (z up, dsm.scenes.builtins), one small scene per
effect the source documents show, with a ``scale`` parameter that scales geometry, camera and the
config's light positions together, and a ``translate`` offset applied after it (far from the
origin in one line of config). Shapes are loaded with ``optimize=False`` so each keeps its
identity (the culling of closed shapes and each shape's error bound read it; the acne split reads
surfaces, not shapes: dsm.maps.lookup.on_own_surface).

A scene that cannot be used (an XML or mesh file that does not load, no sensor, no
triangles, positions that are not finite, triangles too large or too small for float32
normals, a ``closed`` override naming no shape) raises :class:`ConfigError` naming the
config file and the [[scene]] key (dsm.scenes.checks); :func:`check` loads every scene of a
config up front so a run refuses before any work.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.types import DEFAULT_CAMERA, ConfigError, SceneSpec
from .builtins import builtin_geometry
from .camera import far_bound, look_at_sensor, posed_camera
from .checks import check_held, check_loaded, check_options, source_of
from .data import SceneData, finish, scale_light
from .emitters import lights_of
from .files import load_file
from .geometry import make_mesh
from .params import ORIGIN
# read here by callers not yet moved to the names' homes (dsm/perf/bench.py; dsm/tune/tuner.py reads
# look_at_sensor, imported above): kept for them, not used by this module
from .params import FileParams, PlaneBoxParams, TerrainParams  # noqa: F401


def load(spec: SceneSpec, camera_resolution=None, camera=None) -> SceneData:
    """Load one scene with its camera at ``camera_resolution`` (width, height). None: an XML
    scene's own film size, else DEFAULT_CAMERA; given, an XML sensor is re-created at that width
    with its film's aspect ratio, transform and field of view. A scene that cannot be used raises
    ConfigError naming ``spec.source`` and the [[scene]] key (``spec.where``). ``camera``: the
    [camera] pose (a CameraSpec), overriding the scene's own (an XML sensor's too)."""
    if spec.missing:
        raise ConfigError(source_of(spec), f"{spec.where}.{'model' if spec.model else 'file'}", spec.missing)
    if spec.params is not None and spec.params.precision == "camera_relative":
        return _camera_relative(spec, camera_resolution, camera)
    data = _load_builtin(spec, camera_resolution, camera) if spec.builtin else load_file(spec, camera_resolution, camera)
    data.closed_override = spec.closed
    check_loaded(spec, data)
    return data


def _load_builtin(spec: SceneSpec, camera_resolution, camera) -> SceneData:
    """A built-in scene scaled and moved by its placement, its camera posed, the exact frame set."""
    import mitsuba as mi
    w, h = camera_resolution or DEFAULT_CAMERA
    p = spec.params
    shapes, (cam_o, cam_t, *fov), light = builtin_geometry(spec.builtin, p)
    s, t = p.scale, np.asarray(p.translate, float)
    d = {"type": "scene"}
    allv = []
    for name, (v, f) in shapes.items():
        d[name] = make_mesh(name, v * s + t, f)
        allv.append(np.asarray(v, float) * s + t)
    allv = np.concatenate(allv)
    o, tg, up, fv, near, far = posed_camera((np.multiply(cam_o, s) + t, np.multiply(cam_t, s) + t, (0, 0, 1),
                                             (fov or [40])[0], None, None), camera, s, p.translate, source_of(spec))
    d["sensor"] = look_at_sensor(o, tg, up, fv, w, h, near,
                                 far if far is not None else far_bound(o, tg, allv.min(0), allv.max(0)),
                                 camera, source_of(spec))
    scene = mi.load_dict(d, optimize=False)
    data = finish(spec.label, scene, [scale_light(light, s, p.translate)], s)
    data.offset = tuple(float(c) for c in p.translate)
    data.camera_pose = (np.asarray(o, float), np.asarray(tg, float), np.asarray(up, float))
    data.centre_frame({name: (np.asarray(v, float) * s + t, f) for name, (v, f) in shapes.items()})
    return data


# check() loads every scene to refuse a bad one before any work, and a run loads each again: the
# first scene a run loads is check's load handed on instead. One scene at most (the config's first),
# so check holds no more than one scene beyond the one it loads; the next check replaces it and the
# run takes it once (load_checked), so no two users share a loaded scene.
HANDED: list = []            # [((spec, camera resolution, camera), SceneData)] or empty


def check(cfg, keep: bool = False):
    """Load every scene of ``cfg`` (absent optional files aside) before any work starts.

    The first scene that cannot be used raises its ConfigError, with the other scenes' problems
    in its ``more`` list (``dsm plan`` prints them all). Returns the loaded SceneData in config
    order (None for absent files) when ``keep``; else hands the first on to :func:`load_checked`.
    Needs a Mitsuba variant (``env.use_variant``)."""
    HANDED.clear()                              # the previous check's scene released before these load
    loaded, errors, seen, first = [], [], set(), None
    for spec in cfg.scenes:
        sd = None
        if not spec.missing:
            try:
                sd = load(spec, cfg.camera_resolution, cfg.camera)
                check_options(cfg, spec, sd)
                if first is None and not keep:
                    first = ((spec, cfg.camera_resolution, cfg.camera), sd)
            except ConfigError as e:
                if str(e) not in seen:          # a swept file that cannot be read says so once
                    seen.add(str(e))
                    errors.append(e)
        loaded.append(sd if keep else None)
    if errors:
        errors[0].more = errors[1:]
        raise errors[0]
    if first is not None:
        HANDED.append(first)
    return loaded if keep else None


def load_checked(spec: SceneSpec, camera_resolution=None, camera=None) -> SceneData:
    """:func:`load`'s scene, taken from the last :func:`check` where it handed this one on (once), else loaded."""
    if HANDED and HANDED[0][0] == (spec, camera_resolution, camera):
        return HANDED.pop()[1]
    return load(spec, camera_resolution, camera)


def _camera_relative(spec, camera_resolution, camera):
    """The scene as an engine rendering relative to its camera holds it: ``translate`` less the
    camera's world position (float64) before anything is rounded to float32, so the camera sits at
    the origin; the config's lights and camera follow (they move with ``translate``). The camera's
    position moves with ``translate``, so it is found on the scene at the origin (one load of it
    first, where float32 holds it whatever the offset) plus the offset."""
    t = np.asarray(spec.params.translate, float)
    at_origin = replace(spec.params, precision="world", translate=ORIGIN)
    origin = load(replace(spec, params=at_origin), camera_resolution, camera)
    cam = origin.camera_pose[0] + t
    shift = tuple(float(c) for c in t - cam)
    lo, hi = (np.asarray(c, float) for c in origin.bbox)
    check_held(float(np.max(hi - lo)), np.maximum(np.abs(lo + shift), np.abs(hi + shift)), source_of(spec),
                "camera.position" if camera is not None and camera.position is not None else f"{spec.where}.precision",
                "from its camera (camera_relative)", "the scene's distance to the camera")
    data = load(replace(spec, params=replace(at_origin, translate=shift)), camera_resolution, camera)
    data.notes.append(f"camera_relative: positions relative to the camera at "
                      f"({', '.join(f'{c:.9g}' for c in cam)}) in world coordinates")
    return data


def from_mitsuba(scene, label: str = "scene") -> "SceneData":
    """SceneData of an already loaded Mitsuba scene (the integrator plugins' entry)."""
    lights, notes = lights_of(scene)
    return finish(label, scene, lights, 1.0, notes)
