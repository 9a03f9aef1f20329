"""Scenes: built-in procedural scenes, Mitsuba 3 XML files and OBJ/PLY meshes.

Every built-in is made of triangle meshes in code (z up), one small scene per effect the
source documents show, with a ``scale`` parameter that scales geometry, camera and the
config's light positions together. Shapes are loaded with ``optimize=False`` so each keeps
its identity (attribution of acne to the receiver's own shape or another one).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .config import ConfigError, LightSpec, SceneSpec, sweep_params

# ---------------------------------------------------------------- parameters


@dataclass(frozen=True)
class PlaneParams:
    """One 4 x 4 plane tilted ``tilt`` degrees about a horizontal axis at ``azimuth`` degrees; light from above."""
    tilt: float = field(default=45.0, metadata={"min": 0.0})
    azimuth: float = 0.0
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class PlaneBoxParams:
    """A closed unit box resting on an 8 x 8 ground: contact shadows."""
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class LShapeParams:
    """Seed 000, figure 5: a closed L-shaped solid above the ground, light from right above."""
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class FloatingPlateParams:
    """An open 1.5 x 1.5 plate ``gap`` above the ground: the bias/gap threshold of peter-panning."""
    gap: float = field(default=0.2, metadata={"min": 0.0})
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class GrazingParams:
    """The ground and a box lit ``angle`` degrees from the ground's normal (80 to 89: projective aliasing)."""
    angle: float = field(default=85.0, metadata={"min": 0.0})
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class RoomParams:
    """Seed 001, figure 3: a closed 6 x 6 x 3 room (walls facing in) with objects around a point light."""
    scale: float = field(default=1.0, metadata={"min": 1e-30})


@dataclass(frozen=True)
class FileParams:
    """A scene file. Meshes (OBJ/PLY) get a ground under them, a default camera and light."""
    scale: float = field(default=1.0, metadata={"min": 1e-30})
    up: str = field(default="y", metadata={"choices": ("x", "y", "z")})
    ground: str = field(default="yes", metadata={"choices": ("yes", "no")})


BUILTINS = {
    "plane": PlaneParams,
    "plane_box": PlaneBoxParams,
    "l_shape": LShapeParams,
    "floating_plate": FloatingPlateParams,
    "grazing": GrazingParams,
    "room": RoomParams,
}
FILE_SUFFIXES = (".xml", ".obj", ".ply")


def parse_scene(t: dict, source: str, where: str, base: Path) -> list[SceneSpec]:
    """One [[scene]] table, with list-valued parameters swept, into scene specs."""
    if ("builtin" in t) == ("file" in t):
        raise ConfigError(source, where, "a scene needs exactly one of builtin or file", ("builtin", "file"))
    if "builtin" in t:
        name = t["builtin"]
        if not isinstance(name, str) or name not in BUILTINS:
            raise ConfigError(source, f"{where}.builtin", f"unknown scene {name!r}", list(BUILTINS))
        specs = sweep_params(BUILTINS[name], t, source, where, skip=("builtin", "closed"))
        for p in specs:
            _check_builtin(p, source, where)
        closed = _closed_override(t, source, where)
        return [SceneSpec(builtin=name, params=p, label=_label(name, p), closed=closed) for p in specs]
    raw = t["file"]
    if not isinstance(raw, str):
        raise ConfigError(source, f"{where}.file", f"expected a path string, got {raw!r}")
    optional = t.get("optional", False)
    if not isinstance(optional, bool):
        raise ConfigError(source, f"{where}.optional", f"expected true or false, got {optional!r}")
    path = Path(raw).expanduser()
    if not path.is_absolute():
        path = (base / path).resolve()
    if path.suffix.lower() not in FILE_SUFFIXES:
        raise ConfigError(source, f"{where}.file", f"unsupported file type {path.suffix!r}", FILE_SUFFIXES)
    if not path.is_file() and not optional:
        raise ConfigError(source, f"{where}.file", f"no such file: {path} (optional = true skips an absent file)")
    specs = sweep_params(FileParams, t, source, where, skip=("file", "closed", "optional"))
    if not path.is_file():
        return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()),
                          missing=f"skipped: {path} is absent (optional scene)") for p in specs]
    closed = _closed_override(t, source, where)
    if path.suffix.lower() == ".xml" and any(p != FileParams() for p in specs):
        raise ConfigError(source, where, "an XML scene takes no scale/up/ground keys", ("file",))
    return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()), closed=closed) for p in specs]


def _closed_override(t, source, where) -> tuple:
    """``closed = { shape_name = true, ... }``: override detected closedness per shape."""
    raw = t.get("closed", {})
    if not isinstance(raw, dict) or not all(isinstance(v, bool) for v in raw.values()):
        raise ConfigError(source, f"{where}.closed", "expected a table of shape name = true/false")
    return tuple(sorted(raw.items()))


def _check_builtin(p, source, where):
    if isinstance(p, PlaneParams) and not p.tilt < 90:
        raise ConfigError(source, f"{where}.tilt", f"must be below 90 degrees, got {p.tilt}")
    if isinstance(p, GrazingParams) and not p.angle < 90:
        raise ConfigError(source, f"{where}.angle", f"must be below 90 degrees, got {p.angle}")


def _label(name, params, defaults=None) -> str:
    defaults = defaults if defaults is not None else type(params)()
    diff = [f"{k}={getattr(params, k):g}" if isinstance(getattr(params, k), float) else f"{k}={getattr(params, k)}"
            for k in params.__dataclass_fields__ if getattr(params, k) != getattr(defaults, k)]
    return f"{name}({','.join(diff)})" if diff else name


# ---------------------------------------------------------------- geometry helpers

def quad(center, u_half, v_half):
    """Two triangles spanning center +- u_half +- v_half, normal along u x v."""
    c, u, v = (np.asarray(a, float) for a in (center, u_half, v_half))
    verts = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]])


def box(lo, hi):
    """A closed box, outward-facing triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return verts, faces


def prism(profile_xz, y0, y1, fan_center: int):
    """A closed prism: a simple polygon in the xz plane (counter-clockwise seen from -y), extruded along y.

    The caps are a fan from vertex ``fan_center``, which must see the whole polygon.
    """
    prof = np.asarray(profile_xz, float)
    n = len(prof)
    front = np.column_stack([prof[:, 0], np.full(n, y0), prof[:, 1]])
    back = np.column_stack([prof[:, 0], np.full(n, y1), prof[:, 1]])
    verts = np.vstack([front, back])
    faces = []
    order = [(fan_center + k) % n for k in range(n)]
    for a, b in zip(order[1:-1], order[2:]):
        faces.append([fan_center, b, a])              # front cap faces -y
        faces.append([n + fan_center, n + a, n + b])  # back cap faces +y
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    return verts, np.array(faces)[:, ::-1]   # outward: a counter-clockwise (x, z) profile winds inward


def make_mesh(name: str, verts: np.ndarray, faces: np.ndarray):
    import mitsuba as mi
    mesh = mi.Mesh(name, len(verts), len(faces))
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    params.update()
    return mesh


def look_at_sensor(origin, target, up, fov, width, height):
    import mitsuba as mi
    dist = float(np.linalg.norm(np.subtract(origin, target)))
    # clip planes follow the scene's scale (Mitsuba's default near clip is 0.01 world units)
    return {"type": "perspective", "fov": fov, "near_clip": dist * 1e-3, "far_clip": dist * 1e3,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, origin)),
                                                       target=list(map(float, target)),
                                                       up=list(map(float, up))),
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height)}}


def _normalize(v):
    v = np.asarray(v, float)
    return tuple(float(c) for c in v / np.linalg.norm(v))


# ---------------------------------------------------------------- built-in scenes

def _rotation(axis, angle_deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * (k @ k)


def _ground(half=4.0):
    return quad([0, 0, 0], [half, 0, 0], [0, half, 0])


def builtin_geometry(name: str, p):
    """(shapes {name: (verts, faces)}, camera (origin, target), default light) at scale 1."""
    if name == "plane":
        rot = _rotation([math.cos(math.radians(p.azimuth)), math.sin(math.radians(p.azimuth)), 0], p.tilt)
        v, f = quad([0, 0, 0], [2, 0, 0], [0, 2, 0])
        shapes = {"plane": (v @ rot.T, f)}
        return shapes, ((0.7, -5.0, 5.0), (0, 0, 0)), LightSpec("directional", direction=(0.0, 0.0, -1.0))
    if name == "plane_box":
        shapes = {"ground": _ground(), "box": box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])}
        return shapes, ((5.0, -7.0, 6.0), (0, 0, 0.3)), LightSpec("directional", direction=_normalize([-0.4, -0.3, -1]))
    if name == "l_shape":
        # seed 000, figure 5: an L above the ground, its vertical arm on the right, light from right above
        profile = [(-1, 0.5), (1, 0.5), (1, 2.0), (0.7, 2.0), (0.7, 0.8), (-1, 0.8)]
        shapes = {"ground": _ground(), "l_shape": prism(profile, -0.8, 0.8, fan_center=4)}
        return shapes, ((-2.0, -6.0, 5.0), (0, 0, 0.7)), LightSpec("directional", direction=_normalize([-0.35, 0.05, -1]))
    if name == "floating_plate":
        shapes = {"ground": _ground(), "plate": quad([0, 0, p.gap], [0.75, 0, 0], [0, 0.75, 0])}
        return shapes, ((3.0, -5.0, 4.0), (0, 0, 0)), LightSpec("directional", direction=_normalize([0.2, 0.1, -1]))
    if name == "grazing":
        t = math.radians(p.angle)
        shapes = {"ground": _ground(), "box": box([-2.3, -0.3, 0.0], [-1.7, 0.3, 0.6])}
        return shapes, ((0.0, -3.0, 8.0), (0, 0, 0)), LightSpec("directional", direction=(math.sin(t), 0.0, -math.cos(t)))
    if name == "room":
        walls, wf = box([-3, -3, 0], [3, 3, 3])
        profile = [(-0.4, 0.0), (0.4, 0.0), (0.4, 0.3), (0.0, 1.0), (-0.4, 0.3)]     # a house-shaped prism
        shapes = {"room": (walls, wf[:, ::-1]),                     # closed, facing in
                  "cube": box([0.9, 0.6, 0.0], [1.7, 1.4, 0.8]),
                  "pillar": box([-1.9, -1.6, 0.0], [-1.4, -1.1, 2.2]),
                  "house": prism(profile, -2.2, -1.4, fan_center=2),
                  "shelf": quad([-0.6, 1.2, 1.1], [0.6, 0, 0], [0, 0.35, 0])}      # open, floating
        shapes["house"] = (shapes["house"][0] + [-0.2, 0.0, 0.0], shapes["house"][1])
        light = LightSpec("point", position=(0.2, 0.1, 1.8), direction=(0.0, 0.0, -1.0), label="point")
        return shapes, ((2.8, -2.8, 2.7), (-0.6, 0.6, 0.4), 75.0), light
    raise KeyError(name)


def _scale_light(light: LightSpec, s: float) -> LightSpec:
    if light.position is None:
        return light
    from dataclasses import replace
    return replace(light, position=tuple(s * c for c in light.position),
                   target=None if light.target is None else tuple(s * c for c in light.target))


# ---------------------------------------------------------------- loaded scenes

@dataclass
class SceneData:
    label: str
    scene: object                  # mi.Scene
    sensor: object                 # mi.Sensor
    shape_names: list              # by shape_index (order of scene.shapes())
    own_lights: list               # the scene's lights (LightSpec), used by [[light]] type = "scene"
    bbox: tuple                    # (min, max) numpy
    scale: float                   # multiplies the config's light positions
    notes: list = field(default_factory=list)
    closed_override: tuple = ()    # (shape name, closed) pairs from the config
    closed: list = None            # per shape, computed when a culling choice needs it
    closed_reason: list = None

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bbox[1] - self.bbox[0]))

    def lights_for(self, specs) -> list:
        out = []
        for spec in specs:
            if spec.type == "scene":
                out += self.own_lights
            else:
                out.append(_scale_light(spec, self.scale))
        return out


def load(spec: SceneSpec, camera_resolution) -> SceneData:
    import mitsuba as mi
    w, h = camera_resolution
    if spec.builtin:
        p = spec.params
        shapes, (cam_o, cam_t, *fov), light = builtin_geometry(spec.builtin, p)
        s = p.scale
        d = {"type": "scene"}
        for name, (v, f) in shapes.items():
            d[name] = make_mesh(name, v * s, f)
        d["sensor"] = look_at_sensor(np.multiply(cam_o, s), np.multiply(cam_t, s), (0, 0, 1), (fov or [40])[0], w, h)
        scene = mi.load_dict(d, optimize=False)
        data = _finish(spec.label, scene, [_scale_light(light, s)], s)
    elif spec.file.suffix.lower() == ".xml":
        data = _load_xml(spec, w)
    else:
        data = _load_mesh_file(spec, w, h)
    data.closed_override = spec.closed
    return data


def _finish(label, scene, own_lights, scale, notes=()):
    import mitsuba as mi
    bb = scene.bbox()
    bbox = (np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel())
    names = [sh.id() or f"shape{i}" for i, sh in enumerate(scene.shapes())]
    if not scene.sensors():
        raise ValueError(f"scene {label!r} has no sensor")
    return SceneData(label, scene, scene.sensors()[0], names, list(own_lights), bbox, scale, list(notes))


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


def default_light(scene) -> LightSpec:
    """A light for a scene without a point, spot or directional emitter: a point light at its
    first area light (moved 2 % of the way to the scene's centre, off the luminaire's surface),
    or else a directional light from above (the sensor's up) and a little to the side."""
    import mitsuba as mi
    bb = scene.bbox()
    centre = np.array(bb.center(), float).ravel()
    for e in scene.emitters():
        shape = e.get_shape()
        if shape is not None:
            c = np.array(shape.bbox().center(), float).ravel()
            pos = c + 0.02 * (centre - c)
            return LightSpec("point", position=tuple(float(x) for x in pos), direction=_normalize(centre - c),
                             label="point")
    up = np.array(scene.sensors()[0].world_transform() @ mi.Vector3f(0, 1, 0), float).ravel()
    side = np.cross(up, [0.3, 0.5, 0.8])
    return LightSpec("directional", direction=_normalize(-up + 0.3 * side / max(np.linalg.norm(side), 1e-9)),
                     label="directional")


def from_mitsuba(scene, label: str = "scene") -> "SceneData":
    """SceneData of an already loaded Mitsuba scene (the integrator plugins' entry)."""
    lights, notes = lights_of(scene)
    return _finish(label, scene, lights, 1.0, notes)


def _load_xml(spec, width):
    import mitsuba as mi
    scene = mi.load_file(str(spec.file), optimize=False)
    lights, notes = lights_of(scene)
    if not lights:
        lights = [default_light(scene)]
        notes.append(f"no point, spot or directional emitter: dsm added a default {lights[0].type} light "
                     f"({lights[0]})")
    # Re-create the sensor at the requested width, keeping its aspect ratio and transform.
    film = scene.sensors()[0].film().size()
    height = max(1, round(width * film[1] / film[0]))
    sensor = scene.sensors()[0]
    data = _finish(spec.label, scene, lights, 1.0, notes)
    data.sensor = _resized_sensor(sensor, width, height)
    return data


def _resized_sensor(sensor, width, height):
    import mitsuba as mi
    params = mi.traverse(sensor)
    m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    d = {"type": "perspective", "to_world": mi.ScalarTransform4f(m),
         "film": {"type": "hdrfilm", "width": int(width), "height": int(height)}}
    if "x_fov" in params:
        d["fov"] = float(params["x_fov"][0])
        d["fov_axis"] = "x"
    for k in ("near_clip", "far_clip"):
        if k in params:
            d[k] = float(np.ravel(params[k])[0])
    return mi.load_dict(d)


def emitter_to_light(e):
    """A Mitsuba emitter as a LightSpec, or None for kinds the kit does not map (area, env)."""
    import mitsuba as mi
    kind = type(e).__name__.lower()
    text = str(e).lower()
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaDirection):
        d = np.array(e.world_transform() @ mi.Vector3f(0, 0, 1), float).ravel()
        return LightSpec("directional", direction=_normalize(d), label="directional")
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition) and ("spot" in kind or "spot" in text):
        tf = e.world_transform()
        pos = np.array(tf @ mi.Point3f(0, 0, 0), float).ravel()
        axis = np.array(tf @ mi.Vector3f(0, 0, 1), float).ravel()
        params = mi.traverse(e)
        cutoff = float(params["cutoff_angle"][0]) if "cutoff_angle" in params else 20.0
        return LightSpec("spot", position=tuple(float(c) for c in pos), direction=_normalize(axis), cutoff=cutoff, label="spot")
    if mi.has_flag(e.flags(), mi.EmitterFlags.DeltaPosition) and "point" in kind + text:
        params = mi.traverse(e)     # a point light keeps its position as a parameter, not in to_world
        pos = (np.array(params["position"], float).ravel() if "position" in params
               else np.array(e.world_transform() @ mi.Point3f(0, 0, 0), float).ravel())
        return LightSpec("point", position=tuple(float(c) for c in pos), direction=(0.0, 0.0, -1.0), label="point")
    return None


def _load_mesh_file(spec, width, height):
    import mitsuba as mi
    p = spec.params
    up = np.eye(3)["xyz".index(p.up)]
    mesh = mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file),
                         "to_world": mi.ScalarTransform4f().scale(p.scale)})
    bb = mesh.bbox()
    lo, hi = np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel()
    center, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    a, b = [np.eye(3)[k] for k in range(3) if k != "xyz".index(p.up)]
    if np.dot(np.cross(a, b), up) < 0:
        a, b = b, a
    d = {"type": "scene", "mesh": mesh}
    if p.ground == "yes":
        base = center + up * (np.dot(lo - center, up))
        v, f = quad(base, a * size * 1.5, b * size * 1.5)
        d["ground"] = make_mesh("ground", v, f)
    side = _normalize(a * 0.6 - b * 1.0 + up * 0.8)
    cam_o = center + np.asarray(side) * 1.6 * size
    d["sensor"] = look_at_sensor(cam_o, center, up, 40, width, height)
    scene = mi.load_dict(d, optimize=False)
    light = LightSpec("directional", direction=_normalize(-up * 1.0 - a * 0.3 + b * 0.2))
    return _finish(spec.label, scene, [light], p.scale)
