"""Scene files: Mitsuba 3 XML scenes and OBJ/PLY meshes (a ground, a camera and a light added)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from . import exact_frame, xml_scale
from ..core import env
from ..core.types import DEFAULT_CAMERA, ConfigError, LightSpec
from .camera import far_bound, look_at_sensor, posed_camera, reposed_sensor, resized_sensor
from .checks import check_held, check_mesh, source_of
from .data import finish
from .emitters import check_emitters, default_light, describe_light, lights_of
from .geometry import make_mesh, normalize, quad
from .ply import ply_index_problem


def load_file(spec, camera_resolution=None, camera=None):
    """SceneData of a [[scene]] file (XML, OBJ or PLY); a file Mitsuba cannot load is a ConfigError."""
    try:
        if spec.file.suffix.lower() == ".xml":
            return load_xml(spec, camera_resolution, camera)
        return load_mesh_file(spec, *(camera_resolution or DEFAULT_CAMERA), camera=camera)
    except ConfigError:
        raise
    except (RuntimeError, ValueError, OSError) as e:      # Mitsuba's loaders raise RuntimeError
        raise _load_error(spec, e) from None


def _load_error(spec, e) -> ConfigError:
    """The ConfigError of a file Mitsuba failed to load (``e``). A scaled or moved file is loaded
    again as it is: where that fails too, its own error (an XML's lines are the file's, not those of
    the rewritten text) names the file; where it loads, the scale (or translate) is at fault."""
    mesh = spec.file.suffix.lower() != ".xml"
    scale = float(getattr(spec.params, "scale", 1.0) or 1.0)
    moved = any(float(c) for c in getattr(spec.params, "translate", (0.0, 0.0, 0.0)) or (0.0, 0.0, 0.0))
    if scale == 1.0 and not moved:
        return ConfigError(source_of(spec), f"{spec.where}.file", f"cannot load {spec.file}: {mitsuba_message(e, mesh)}")
    plain = _plain_load_error(spec)
    if plain is not None:
        return ConfigError(source_of(spec), f"{spec.where}.file", f"cannot load {spec.file}: "
                           f"{mitsuba_message(plain, mesh)}")
    key, how = ("scale", f"scaled by {scale:g}") if scale != 1.0 else ("translate", "moved")
    return ConfigError(source_of(spec), f"{spec.where}.{key}", f"cannot load {spec.file} {how} (it loads as it "
                       f"is): {mitsuba_message(e, mesh)}")


def _plain_load_error(spec):
    """Mitsuba's error loading the file of ``spec`` unscaled and unmoved, None where it loads."""
    import mitsuba as mi
    try:
        if spec.file.suffix.lower() == ".xml":
            load_xml_scene(spec.file)
        else:
            mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file)})
        return None
    except (RuntimeError, ValueError, OSError) as e:
        return e


def mitsuba_message(e, mesh_file: bool = False) -> str:
    """A Mitsuba loader's error on one line, without its C++ source locations and the plugin
    chatter (the file is named by the caller; an XML error keeps its line and column)."""
    msg = re.sub(r"\[[\w./\\-]+\.(?:cpp|h|inl):\d+\]\s*", "", str(e))
    msg = msg.replace('At dictionary node "root": ', "")
    msg = re.sub(r'At \S+ \((line \d+, col \d+)\): ', r"\1: ", msg)
    msg = re.sub(r'failed to instantiate \w+ plugin of type "[^"]*": ', "", msg)
    if mesh_file:
        msg = re.sub(r'\[\w+\] Error while loading \w+ file "[^"]*": ', "", msg)
        msg = re.sub(r'"[^"]*\.(?:ply|obj|PLY|OBJ)": ', "", msg)
    msg = " ".join(msg.split())
    return msg if len(msg) <= 400 else msg[:400] + " ..."


def _precheck_file(spec):
    """Problems Mitsuba reports badly or not at all in a [[scene]] file (precheck_path)."""
    precheck_path(spec.file, source_of(spec), f"{spec.where}.file")


def precheck_path(path: Path, source: str, key: str):
    """Problems Mitsuba reports badly or not at all: an empty file, a mesh without faces, a file that
    is no PLY; a ConfigError naming ``source`` and ``key``."""
    try:
        size = path.stat().st_size
        if size == 0:
            raise ConfigError(source, key, f"{path} is empty")
        suffix = path.suffix.lower()
        if suffix == ".obj":
            data = path.read_bytes()
            if re.search(rb"(?m)^[ \t]*f[ \t]", data) is None:
                raise ConfigError(source, key, f"{path} has no faces (no 'f' lines): dsm needs a triangle mesh")
            # a record cut short (a file truncated mid-line): Mitsuba would load the rest silently
            short = re.search(rb"(?m)^[ \t]*([vf])[ \t]+\S+(?:[ \t]+\S+)?[ \t]*\r?$", data)
            if short is not None:
                line = data.count(b"\n", 0, short.start()) + 1
                what = "vertex with fewer than 3 coordinates" if short.group(1) == b"v" else "face with fewer than 3 corners"
                raise ConfigError(source, key, f"{path}: line {line} is a {what} (a file cut short?)")
        elif suffix == ".ply":
            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
            if not head.startswith(b"ply"):
                raise ConfigError(source, key, f"{path} is not a PLY file (it does not start with 'ply')")
            end = head.find(b"end_header")
            if end < 0:
                raise ConfigError(source, key, f"{path}: the PLY header has no end_header")
            m = re.search(rb"element\s+face\s+(\d+)", head[:end])
            if m is None or int(m.group(1)) == 0:
                raise ConfigError(source, key, f"{path} has no faces (PLY element face: "
                                  f"{m.group(1).decode() if m else 'absent'}): dsm needs a triangle mesh")
            bad = ply_index_problem(path, head, end)
            if bad:
                raise ConfigError(source, key, f"{path}: {bad}")
    except OSError as e:
        raise ConfigError(source, key, f"cannot read {path}: {e.strerror or e}") from None


def mesh_arrays(path, source: str = "<scene>", key: str = "scene.mesh") -> tuple:
    """A PLY or OBJ file's (vertices (n, 3) float64, faces (m, 3) int64) as Mitsuba loads it (its own
    frame, float32 positions), checked as a [[scene]] file is: a file Mitsuba cannot read, or without
    faces, finite positions or extent, is a ConfigError naming ``source`` and ``key``."""
    import mitsuba as mi
    path = Path(path)
    precheck_path(path, source, key)
    if mi.variant() is None:       # a config read before its run sets one (a built-in's mesh): the default
        env.use_variant()
    try:
        mesh = mi.load_dict({"type": path.suffix.lower()[1:], "filename": str(path)})
    except (RuntimeError, ValueError, OSError) as e:
        raise ConfigError(source, key, f"cannot load {path}: {mitsuba_message(e, True)}") from None
    v = np.array(mesh.vertex_positions_buffer(), np.float64).reshape(-1, 3)
    f = np.array(mesh.faces_buffer(), np.int64).reshape(-1, 3)
    if len(f) == 0 or len(v) == 0 or not np.isfinite(v).all():
        raise ConfigError(source, key, f"{path}: has no faces or a vertex that is not finite")
    if not float(np.ptp(v, axis=0).max()) > 0.0:
        raise ConfigError(source, key, f"{path}: has no extent (every vertex at one point)")
    return v, f


def load_xml(spec, camera_resolution, camera=None):
    """SceneData of a Mitsuba 3 XML scene: its first sensor (resized, reposed by [camera]), its emitters."""
    _precheck_file(spec)
    scene = load_xml_scene(spec.file, spec.params.scale, spec.params.translate)
    if not scene.sensors():
        raise ConfigError(source_of(spec), f"{spec.where}.file", f"{spec.file} has no <sensor>: dsm takes the camera "
                          "from an XML scene's first sensor; add one")
    lights, notes = lights_of(scene)
    check_emitters(spec, lights)
    if not lights:
        lights = [default_light(scene)]
        notes.append(f"no point, spot or directional emitter: dsm added a default {describe_light(lights[0])}")
    sensor = scene.sensors()[0]
    data = finish(spec.label, scene, lights, spec.params.scale, notes)
    if any(spec.params.translate) or exact_frame.centre_for(data.bbox) is not None:
        _moved_xml(data, spec)          # moved by translate, or authored far from the origin in its own file
    if camera_resolution is not None:
        # [camera] resolution: the sensor re-created at that width, with its film's aspect ratio,
        # transform and field of view; without it the XML's own sensor and film are the camera
        film = sensor.film().size()
        width = int(camera_resolution[0])
        data.sensor = resized_sensor(sensor, width, max(1, round(width * film[1] / film[0])))
    if camera is not None:
        data.sensor = reposed_sensor(data.sensor, camera, data.bbox, source_of(spec))
        data.camera_pose = None           # the reposed sensor's own matrix, not the file's pose
    return data


def _moved_xml(data, spec):
    """An XML scene given a ``translate``: its offset (the [[light]] positions move with it), its
    extent checked against float32 at the offset, and, far from the origin, the exact side traced in
    the same file loaded moved by translate minus the scene's centre (float64: its vertices rounded
    near the origin, the shapes in the same order)."""
    p = data.offset = tuple(float(c) for c in spec.params.translate)
    centre = exact_frame.centre_for(data.bbox)
    size = float(np.max(data.bbox[1] - data.bbox[0]))
    if centre is not None:
        local = load_xml_scene(spec.file, spec.params.scale, tuple(np.asarray(p, np.float64) - centre))
        # its size from the copy near the origin: the bounds at the offset are rounded to its steps
        size = float(np.max(np.array(local.bbox().max, np.float64) - np.array(local.bbox().min, np.float64)))
    if any(p):
        check_held(size, p, source_of(spec), f"{spec.where}.translate", "from the origin")
    elif centre is not None:            # authored far away: its own coordinates hold it, or not
        check_held(size, centre, source_of(spec), f"{spec.where}.file", f"from the origin (where {spec.file} "
                   "puts it),", "the scene's own coordinates")
    if centre is not None:
        data.use_exact_scene(centre, local)
        # the camera's pose in float64 from the moved file's sensor (its matrix rounded near the origin,
        # not at the offset); a mirrored frame, which look_at cannot rebuild, keeps the world matrix
        m = np.array(local.sensors()[0].world_transform().matrix, np.float64).reshape(4, 4)
        if np.linalg.det(m[:3, :3]) > 0:
            o = m[:3, 3] + centre
            data.camera_pose = (o, o + m[:3, 2], m[:3, 1])


def load_xml_scene(path, scale: float = 1.0, translate=(0.0, 0.0, 0.0)):
    """The Mitsuba scene of an XML file, every element scaled by ``scale`` then moved by ``translate``
    (xml_scale) when not the identity, its relative file names resolved against the file's folder as
    mi.load_file resolves them."""
    import mitsuba as mi
    if scale == 1.0 and not any(translate):
        return mi.load_file(str(path), optimize=False)
    text = xml_scale.scaled_text(path, scale, translate)
    resolver = mi.file_resolver()
    resolver_paths = [str(p) for p in resolver]           # restored after: the resolver is the process's
    resolver.prepend(str(Path(path).resolve().parent))
    try:
        return mi.load_string(text, optimize=False)
    finally:
        resolver.clear()
        for p in resolver_paths:
            resolver.append(p)


def load_mesh_file(spec, width, height, camera=None):
    """SceneData of an OBJ/PLY mesh placed by its params, with a ground, a default camera and light."""
    import mitsuba as mi
    p = spec.params
    _precheck_file(spec)
    up = np.eye(3)["xyz".index(p.up)]
    # a named model's units (Crytek's Sponza in cm) scale its file only: the config's poses are in its frame
    to_world = mi.ScalarTransform4f().translate([float(c) for c in p.translate]).scale(p.scale * spec.units)
    mesh = mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file), "to_world": to_world})
    check_mesh(mesh, "mesh", spec)      # before the camera is posed from its bounds (a 1e-20 mesh has none)
    bb = mesh.bbox()
    lo, hi = np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel()
    mesh64 = None
    if exact_frame.centre_for((lo, hi)) is not None:
        # far from the origin: the file's vertices scaled in float32 as at the origin, then moved in
        # float64, for the exact frame and for the ground and camera both frames share
        local = mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file),
                              "to_world": mi.ScalarTransform4f().scale(p.scale * spec.units)})
        mesh64 = (np.asarray(local.vertex_positions_buffer(), np.float64).reshape(-1, 3) + np.asarray(p.translate, float),
                  np.asarray(local.faces_buffer(), np.int64).reshape(-1, 3))
        lo, hi = mesh64[0].min(0), mesh64[0].max(0)
    center, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    if p.precision == "world":       # the mesh and its ground (3 diagonals across) rounded at the offset
        held = max(float(np.max(hi - lo)), 3 * size if p.ground == "yes" else 0.0)
        if any(p.translate):
            check_held(held, p.translate, source_of(spec), f"{spec.where}.translate", "from the origin")
        else:                        # authored far away in the file: its own coordinates, as a translate's
            check_held(held, center, source_of(spec), f"{spec.where}.file", f"from the origin (where {spec.file} "
                       "puts it),", "the file's own coordinates")
    a, b = [np.eye(3)[k] for k in range(3) if k != "xyz".index(p.up)]
    if np.dot(np.cross(a, b), up) < 0:
        a, b = b, a
    d = {"type": "scene", "mesh": mesh}
    if p.ground == "yes":
        base = center + up * (np.dot(lo - center, up))
        v, f = quad(base, a * size * 1.5, b * size * 1.5)
        d["ground"] = make_mesh("ground", v, f)
    side = normalize(a * 0.6 - b * 1.0 + up * 0.8)
    cam_o = center + np.asarray(side) * 1.6 * size
    o, tg, upv, fv, near, far = posed_camera((cam_o, center, up, 40.0, None, None), camera, p.scale, p.translate,
                                         source_of(spec))
    lo_all, hi_all = (lo, hi) if p.ground != "yes" else (np.minimum(lo, center - size * 1.5), np.maximum(hi, center + size * 1.5))
    d["sensor"] = look_at_sensor(o, tg, upv, fv, width, height, near,
                                 far if far is not None else far_bound(o, tg, lo_all, hi_all), camera, source_of(spec))
    scene = mi.load_dict(d, optimize=False)
    light = LightSpec("directional", direction=normalize(-up * 1.0 - a * 0.3 + b * 0.2))
    data = finish(spec.label, scene, [light], p.scale)
    data.offset = tuple(float(c) for c in p.translate)
    data.camera_pose = (np.asarray(o, float), np.asarray(tg, float), np.asarray(upv, float))
    data.checked = ("mesh",)              # checked before the camera was posed
    if mesh64 is not None:
        data.centre_frame({"mesh": mesh64, **({"ground": (v, f)} if "ground" in d else {})})
    return data
