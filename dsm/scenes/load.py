"""Scenes: built-in procedural scenes, Mitsuba 3 XML files and OBJ/PLY meshes.

Every built-in is made of triangle meshes in code (z up), one small scene per effect the
source documents show, with a ``scale`` parameter that scales geometry, camera and the
config's light positions together, and a ``translate`` offset applied after it (far from the
origin in one line of config). Shapes are loaded with ``optimize=False`` so each keeps its
identity (attribution of acne to the receiver's own shape or another one).

A scene that cannot be used (an XML or mesh file that does not load, no sensor, no
triangles, positions that are not finite, triangles too large or too small for float32
normals, a ``closed`` override naming no shape) raises :class:`ConfigError` naming the
config file and the [[scene]] key; :func:`check` loads every scene of a config up front so a
run refuses before any work.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from . import exact_frame
from ..types import DEFAULT_CAMERA, ConfigError, LightSpec, SceneSpec, sweep_params

ORIGIN = (0.0, 0.0, 0.0)
# Mitsuba computes a triangle's normal as normalize(cross(e1, e2)) in float32, squaring the cross
# product's length: above sqrt(FLT_MAX) = 1.8e19 it overflows to a zero normal (plane_box, whose
# largest |e1 x e2| is 64 at scale 1, loses its receivers between scale 5e8 and 7e8), below
# sqrt(FLT_MIN) = 1.1e-19 it flushes to zero and the normal is NaN (the unit box at scale 1e-10).
CROSS_MAX = 1e19
CROSS_MIN = 2e-19

# ---------------------------------------------------------------- parameters

# How the simulated engine holds positions (the map's build and lookup): ``world``, float32 world
# coordinates (the geometry rounded at its offset); ``camera_relative``, positions relative to the
# camera, shifted in float64 before rounding (Unreal's large world coordinates, Unity HDRP's
# camera-relative rendering). The exact side is exact in both (dsm.scenes.exact_frame).
PRECISIONS = ("world", "camera_relative")


@dataclass(frozen=True)
class Placement:
    """Where a built-in scene (or a mesh file) sits: ``scale`` multiplies geometry, camera and the
    config's light positions; ``translate`` then moves all of them (far-from-origin cases)."""
    scale: float = field(default=1.0, metadata={"min": 1e-30})
    translate: tuple = field(default=ORIGIN, metadata={"doc": "world offset [x, y, z] after scale"})
    precision: str = field(default="world", metadata={"choices": PRECISIONS})


@dataclass(frozen=True)
class PlaneParams(Placement):
    """One 4 x 4 plane tilted ``tilt`` degrees about a horizontal axis at ``azimuth`` degrees; light from above."""
    tilt: float = field(default=45.0, metadata={"min": 0.0})
    azimuth: float = 0.0


@dataclass(frozen=True)
class PlaneBoxParams(Placement):
    """A closed unit box resting on an 8 x 8 ground: contact shadows."""


@dataclass(frozen=True)
class LShapeParams(Placement):
    """Seed 000, figure 5: a closed L-shaped solid above the ground, light from right above."""


@dataclass(frozen=True)
class FloatingPlateParams(Placement):
    """An open 1.5 x 1.5 plate ``gap`` above the ground: the bias/gap threshold of peter-panning."""
    gap: float = field(default=0.2, metadata={"min": 0.0})


@dataclass(frozen=True)
class StackedPlatesParams(Placement):
    """Two open plates over the ground, a 0.75 x 1.5 one at ``high`` over half of a 1.5 x 1.5 one
    at ``low``: occluders at two depths, the classic light leak of variance shadow maps."""
    low: float = field(default=0.25, metadata={"min": 0.0})
    high: float = field(default=2.0, metadata={"min": 0.0})


@dataclass(frozen=True)
class GrazingParams(Placement):
    """The ground and a box lit ``angle`` degrees from the ground's normal (80 to 89: projective aliasing)."""
    angle: float = field(default=85.0, metadata={"min": 0.0})


@dataclass(frozen=True)
class RoomParams(Placement):
    """Seed 001, figure 3: a closed 6 x 6 x 3 room (walls facing in) with objects around a point light."""


@dataclass(frozen=True)
class DoubleTorusParams(Placement):
    """Seed 000, figure 6: a closed genus-2 solid (a double torus, 6,400 triangles) tilted above the ground."""


@dataclass(frozen=True)
class LongGroundParams(Placement):
    """A 200 x 20 ground with posts (0.4 x 0.4 x 4) every 10 units along both sides, the camera near
    the ground at one end looking along it: perspective aliasing, the cascades' scene."""


@dataclass(frozen=True)
class TerrainParams(Placement):
    """A real terrain in metres (dsm.scenes.terrain): 30 x 32 km of the Jacksboro fault DEM, 236 to 1076 m
    high, 275,772 triangles (every ``stride``-th sample), the camera on a ridge above its
    south-west, a low sun: cascades and scale on geometry nobody here made."""
    stride: int = field(default=1, metadata={"min": 1})


@dataclass(frozen=True)
class FileParams(Placement):
    """A scene file. Meshes (OBJ/PLY) get a ground under them, a default camera and light."""
    up: str = field(default="y", metadata={"choices": ("x", "y", "z")})
    ground: str = field(default="yes", metadata={"choices": ("yes", "no")})


BUILTINS = {
    "plane": PlaneParams,
    "plane_box": PlaneBoxParams,
    "l_shape": LShapeParams,
    "floating_plate": FloatingPlateParams,
    "stacked_plates": StackedPlatesParams,
    "grazing": GrazingParams,
    "room": RoomParams,
    "double_torus": DoubleTorusParams,
    "long_ground": LongGroundParams,
    "terrain": TerrainParams,
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
            _check_builtin(name, p, source, where)
        closed = _closed_override(t, source, where)
        shape_names = list(builtin_geometry(name, specs[0])[0])
        for shape, _ in closed:
            if shape not in shape_names:
                raise ConfigError(source, f"{where}.closed.{shape}", f"no shape named {shape!r} in {name}", shape_names)
        return [SceneSpec(builtin=name, params=p, label=_label(name, p), closed=closed, source=source, where=where)
                for p in specs]
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
    if path.is_dir():
        raise ConfigError(source, f"{where}.file", f"{path} is a folder, not a scene file", FILE_SUFFIXES)
    if not path.is_file() and not optional:
        raise ConfigError(source, f"{where}.file", f"no such file: {path} (optional = true skips an absent file)")
    specs = sweep_params(FileParams, t, source, where, skip=("file", "closed", "optional"))
    if not path.is_file():
        return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()),
                          missing=f"skipped: {path} is absent (optional scene)", source=source, where=where)
                for p in specs]
    closed = _closed_override(t, source, where)
    if path.suffix.lower() == ".xml" and any(p != FileParams() for p in specs):
        given = [f.name for f in fields(FileParams) if any(getattr(p, f.name) != getattr(FileParams(), f.name)
                                                            for p in specs)]
        raise ConfigError(source, f"{where}.{given[0]}", "an XML scene takes no "
                          f"{'/'.join(f.name for f in fields(FileParams))} keys: its geometry, camera and lights "
                          "are the file's, in its own world coordinates", ("file", "closed", "optional"))
    return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()), closed=closed, source=source,
                      where=where) for p in specs]


def _closed_override(t, source, where) -> tuple:
    """``closed = { shape_name = true, ... }``: override detected closedness per shape."""
    raw = t.get("closed", {})
    if not isinstance(raw, dict) or not all(isinstance(v, bool) for v in raw.values()):
        raise ConfigError(source, f"{where}.closed", "expected a table of shape name = true/false")
    return tuple(sorted(raw.items()))


def _check_builtin(name, p, source, where):
    if isinstance(p, PlaneParams) and not p.tilt < 90:
        raise ConfigError(source, f"{where}.tilt", f"must be below 90 degrees, got {p.tilt}")
    if isinstance(p, GrazingParams) and not p.angle < 90:
        raise ConfigError(source, f"{where}.angle", f"must be below 90 degrees, got {p.angle}")
    shapes = builtin_geometry(name, p)[0]
    if p.precision == "world":           # camera-relative: checked where the camera is known (load)
        v = np.concatenate([np.asarray(v, float).reshape(-1, 3) for v, _ in shapes.values()])
        _check_held(float(np.ptp(v, axis=0).max()) * p.scale, p.translate, source, f"{where}.translate",
                    "from the origin")
    lo, hi = scale_range(name, p, shapes)
    if not lo <= p.scale <= hi:
        raise ConfigError(source, f"{where}.scale", f"{p.scale:g} is outside {lo:.2g} to {hi:.2g}, the scales at which "
                          "Mitsuba's float32 triangle normals of this scene neither overflow nor underflow")


def _check_held(size: float, offset, source: str, key: str, where_from: str, what: str = "the offset"):
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


def _cross_lengths(verts, faces) -> np.ndarray:
    """|e1 x e2| (twice the area) of every triangle, in float64."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    return np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def scale_range(name: str, p, shapes=None) -> tuple:
    """The scales at which every triangle of a built-in keeps a float32 normal (see CROSS_MAX);
    ``shapes``: its geometry where the caller has it."""
    shapes = builtin_geometry(name, p)[0] if shapes is None else shapes
    c = np.concatenate([_cross_lengths(v, f) for v, f in shapes.values()])
    c = c[c > 0]
    return math.sqrt(CROSS_MIN / c.min()), math.sqrt(CROSS_MAX / c.max())


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, tuple):
        return "[" + ",".join(_fmt(x) for x in v) + "]"
    return str(v)


def _label(name, params, defaults=None) -> str:
    defaults = defaults if defaults is not None else type(params)()
    diff = [f"{k}={_fmt(getattr(params, k))}" for k in params.__dataclass_fields__
            if getattr(params, k) != getattr(defaults, k)]
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
    """A Mitsuba mesh ``name`` of vertex positions ``verts`` (n, 3) and triangles ``faces`` (m, 3)."""
    import mitsuba as mi
    mesh = mi.Mesh(name, len(verts), len(faces))
    params = mi.traverse(mesh)
    with np.errstate(over="ignore"):     # beyond float32: inf, refused by _check_loaded in one line
        params["vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    params.update()
    return mesh


def look_at_sensor(origin, target, up, fov, width, height, near=None, far=None, camera=None, source="<config>"):
    """A perspective sensor dict. Clip planes follow the scene's scale (Mitsuba's default near clip is
    0.01 world units): ``near`` default 1/1000 of the distance to the target, ``far`` 1000 times it.
    Clips that cross are a ConfigError naming the [camera] key of ``camera`` that set one alone."""
    import mitsuba as mi
    dist = float(np.linalg.norm(np.subtract(origin, target)))
    near = dist * 1e-3 if near is None else float(near)
    far = dist * 1e3 if far is None else float(far)
    with np.errstate(over="ignore"):             # a far beyond float32 is inf: still beyond near
        crossed = not np.float32(near) < np.float32(far)   # Mitsuba compares them in float32
    if crossed:                                  # else Mitsuba's RuntimeError, with no key to name
        raise clip_error(near, far, camera, source)
    return {"type": "perspective", "fov": fov, "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, origin)),
                                                       target=list(map(float, target)),
                                                       up=list(map(float, up))),
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height)}}


def clip_error(near, far, camera, source="<config>"):
    """The error for a near clip not below the far clip: one of them given alone in [camera]."""
    given = {k for k in ("near", "far") if camera is not None and getattr(camera, k) is not None}
    if given == {"far"}:
        return ConfigError(source, "camera.far", f"{camera.far:g} is not beyond the near clip it goes with "
                           f"({near:.3g} world units: the scene's, or 1/1000 of the camera's distance to its "
                           "target); give a larger far, or camera.near below it")
    if given == {"near"}:
        return ConfigError(source, "camera.near", f"{camera.near:g} is not below the far clip it goes with "
                           f"({far:.3g} world units: the scene's, or just beyond its farthest point); give a "
                           "smaller near, or camera.far above it")
    return ConfigError(source, "camera", f"the near clip ({near:.3g}) is not below the far clip ({far:.3g})",
                       ("near", "far"))


def far_bound(origin, target, bbox_min, bbox_max) -> float:
    """A sensible far clip: the view depth of the scene's farthest bounding-box corner (a bound on the
    farthest receiver), 1 % beyond it."""
    fwd = np.subtract(target, origin).astype(float)
    fwd /= np.linalg.norm(fwd)
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    return max(float(((corners - np.asarray(origin, float)) @ fwd).max()), 1e-30) * 1.01


NEAR_MIN = 1e-12     # the smallest near clip, relative to the camera's distance to its target (1e-19 fails)


def posed_camera(default, camera, scale=1.0, offset=ORIGIN, source="<config>"):
    """(origin, target, up, fov, near, far) of a scene's camera: the scene's own ``default`` pose
    (origin, target, up, fov, near or None, far or None, world units) with the [camera] keys that
    are given (``camera``: a CameraSpec or None) scaled by ``scale`` and moved by ``offset`` as the
    config's light positions are. A pose that cannot be looked from (the position on the target,
    the up along the view) is a ConfigError of ``source`` naming the [camera] key."""
    o, t, up, fov, near, far = default
    if camera is not None:
        off = np.asarray(offset, float)
        if camera.position is not None:
            o = np.asarray(camera.position, float) * scale + off
        if camera.target is not None:
            t = np.asarray(camera.target, float) * scale + off
        up = camera.up if camera.up is not None else up
        fov = camera.fov if camera.fov is not None else fov
        near = camera.near * scale if camera.near is not None else near
        far = camera.far * scale if camera.far is not None else far
    key = "target" if camera is not None and camera.target is not None else "position"
    if np.allclose(np.asarray(o, float), np.asarray(t, float)):
        raise ConfigError(source, f"camera.{key}", f"the camera's position {tuple(float(c) for c in o)} equals "
                          f"its target (the scene's own pose, where the [camera] key is not given)")
    fwd, upv = np.subtract(t, o).astype(float), np.asarray(up, float)
    dist = float(np.linalg.norm(fwd))
    if camera is not None and camera.near is not None and near < NEAR_MIN * dist:
        raise ConfigError(source, "camera.near", f"{camera.near:g} is below {NEAR_MIN:g} of the camera's distance "
                          f"to its target ({dist / scale:g}): the float32 projection of the camera's rays breaks "
                          f"down there (no ray would reach the scene); give at least {NEAR_MIN * dist / scale:.3g}")
    if np.linalg.norm(np.cross(fwd, upv)) <= 1e-6 * np.linalg.norm(fwd) * np.linalg.norm(upv):
        raise ConfigError(source, "camera.up", f"{tuple(float(c) for c in up)} is along the view direction "
                          f"(target - position = {tuple(float(c) for c in fwd)}); give an up across it")
    return np.asarray(o, float), np.asarray(t, float), tuple(float(c) for c in up), float(fov), near, far


def normalize(v):
    """``v`` as a unit vector (float64); a zero or non-finite vector is a ValueError."""
    v = np.asarray(v, float)
    n = float(np.linalg.norm(v))
    if not (n > 0 and math.isfinite(n)):
        raise ValueError(f"cannot normalize the vector {tuple(float(c) for c in v)}: it is zero or not finite")
    return tuple(float(c) for c in v / n)


def polycube(xs, ys, zs, solid):
    """The boundary of a union of grid cells as outward-wound quads (welded vertices):
    ``solid[i, j, k]`` fills the cell [xs[i], xs[i+1]] x [ys[j], ys[j+1]] x [zs[k], zs[k+1]]."""
    solid = np.asarray(solid, bool)
    nx, ny, nz = solid.shape
    vid = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k
    S = np.pad(solid, 1)
    quads = []
    for i, j, k in zip(*np.nonzero(solid)):
        if not S[i, j + 1, k + 1]:
            quads.append([vid(i, j, k), vid(i, j, k + 1), vid(i, j + 1, k + 1), vid(i, j + 1, k)])
        if not S[i + 2, j + 1, k + 1]:
            quads.append([vid(i + 1, j, k), vid(i + 1, j + 1, k), vid(i + 1, j + 1, k + 1), vid(i + 1, j, k + 1)])
        if not S[i + 1, j, k + 1]:
            quads.append([vid(i, j, k), vid(i + 1, j, k), vid(i + 1, j, k + 1), vid(i, j, k + 1)])
        if not S[i + 1, j + 2, k + 1]:
            quads.append([vid(i, j + 1, k), vid(i, j + 1, k + 1), vid(i + 1, j + 1, k + 1), vid(i + 1, j + 1, k)])
        if not S[i + 1, j + 1, k]:
            quads.append([vid(i, j, k), vid(i, j + 1, k), vid(i + 1, j + 1, k), vid(i + 1, j, k)])
        if not S[i + 1, j + 1, k + 2]:
            quads.append([vid(i, j, k + 1), vid(i + 1, j, k + 1), vid(i + 1, j + 1, k + 1), vid(i, j + 1, k + 1)])
    X, Y, Z = np.meshgrid(np.asarray(xs, float), np.asarray(ys, float), np.asarray(zs, float), indexing="ij")
    verts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    used, inv = np.unique(np.array(quads), return_inverse=True)
    return verts[used], inv.reshape(-1, 4)


def catmull_clark(verts, quads):
    """One Catmull-Clark step of a closed quad mesh: four quads per quad, wound as their parent."""
    V, Q = np.asarray(verts, float), np.asarray(quads, np.int64)
    nv, nq = len(V), len(Q)
    face_pt = V[Q].mean(1)
    edges = np.stack([Q, np.roll(Q, -1, axis=1)], -1).reshape(-1, 2)       # quad f's edge k: (Q[f,k], Q[f,k+1])
    uniq, inv = np.unique(np.sort(edges, 1), axis=0, return_inverse=True)
    inv = inv.ravel()
    fsum = np.zeros((len(uniq), 3))
    np.add.at(fsum, inv, np.repeat(face_pt, 4, axis=0))
    edge_pt = (V[uniq[:, 0]] + V[uniq[:, 1]] + fsum) / 4                    # two ends + two face points
    valence = np.zeros(nv)
    np.add.at(valence, uniq.ravel(), 1)
    F = np.zeros((nv, 3))
    np.add.at(F, Q.ravel(), np.repeat(face_pt, 4, axis=0))
    mid = (V[uniq[:, 0]] + V[uniq[:, 1]]) / 2
    R = np.zeros((nv, 3))
    np.add.at(R, uniq[:, 0], mid)
    np.add.at(R, uniq[:, 1], mid)
    n = valence[:, None]
    moved = (F / n + 2 * R / n + (n - 3) * V) / n
    E = inv.reshape(nq, 4) + nv
    C = np.arange(nq) + nv + len(uniq)
    out = [np.stack([Q[:, k], E[:, k], C, E[:, (k - 1) % 4]], 1) for k in range(4)]
    return np.vstack([moved, edge_pt, face_pt]), np.concatenate(out)


def double_torus(levels: int = 3):
    """A closed, outward-wound genus-2 triangle mesh: a slab with two square holes (a polycube of
    13 cells) smoothed by Catmull-Clark; 100 * 4**levels triangles, centred, about 2.4 x 1.4 x 0.5."""
    solid = np.ones((5, 3, 1), bool)
    solid[1, 1, 0] = solid[3, 1, 0] = False
    v, q = polycube([0, 1, 3, 4, 6, 7], [0, 1, 3, 4], [0, 1.5], solid)
    for _ in range(levels):
        v, q = catmull_clark(v, q)
    v = (v - (v.max(0) + v.min(0)) / 2) * 0.35
    return v, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


# ---------------------------------------------------------------- built-in scenes

def rotation(axis, angle_deg):
    """The 3 x 3 rotation by ``angle_deg`` degrees about ``axis`` (Rodrigues' formula)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * (k @ k)


def _ground(half=4.0):
    return quad([0, 0, 0], [half, 0, 0], [0, half, 0])


def builtin_geometry(name: str, p):
    """(shapes {name: (verts, faces)}, camera (origin, target), default light) at scale 1."""
    if name == "plane":
        rot = rotation([math.cos(math.radians(p.azimuth)), math.sin(math.radians(p.azimuth)), 0], p.tilt)
        v, f = quad([0, 0, 0], [2, 0, 0], [0, 2, 0])
        shapes = {"plane": (v @ rot.T, f)}
        return shapes, ((0.7, -5.0, 5.0), (0, 0, 0)), LightSpec("directional", direction=(0.0, 0.0, -1.0))
    if name == "plane_box":
        shapes = {"ground": _ground(), "box": box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])}
        return shapes, ((5.0, -7.0, 6.0), (0, 0, 0.3)), LightSpec("directional", direction=normalize([-0.4, -0.3, -1]))
    if name == "l_shape":
        # seed 000, figure 5: an L above the ground, its vertical arm on the right, light from right above
        profile = [(-1, 0.5), (1, 0.5), (1, 2.0), (0.7, 2.0), (0.7, 0.8), (-1, 0.8)]
        shapes = {"ground": _ground(), "l_shape": prism(profile, -0.8, 0.8, fan_center=4)}
        return shapes, ((-2.0, -6.0, 5.0), (0, 0, 0.7)), LightSpec("directional", direction=normalize([-0.35, 0.05, -1]))
    if name == "floating_plate":
        shapes = {"ground": _ground(), "plate": quad([0, 0, p.gap], [0.75, 0, 0], [0, 0.75, 0])}
        return shapes, ((3.0, -5.0, 4.0), (0, 0, 0)), LightSpec("directional", direction=normalize([0.2, 0.1, -1]))
    if name == "stacked_plates":
        shapes = {"ground": _ground(), "low": quad([0, 0, p.low], [0.75, 0, 0], [0, 0.75, 0]),
                  "high": quad([-0.375, 0, p.high], [0.375, 0, 0], [0, 0.75, 0])}
        # the camera low, to see the ground under the plates, where the leak is; the light straight down
        return shapes, ((2.4, -3.0, 0.8), (0.0, 0.0, 0.1), 40.0), LightSpec("directional", direction=(0.0, 0.0, -1.0))
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
    if name == "double_torus":
        # seed 000, figure 6: the double torus over a plane; tilted so the light from above grazes
        # its far side and sees into both holes (midpoint's self-unshadowing shows at its lower left)
        v, f = double_torus()
        v = v @ rotation([1, 0.3, 0], 20).T + [0.0, 0.0, 0.9]
        shapes = {"ground": _ground(), "double_torus": (v, f)}
        return shapes, ((1.0, -4.5, 3.8), (0, 0, 0.5)), LightSpec("directional", direction=normalize([0.3, -0.2, -1]))
    if name == "long_ground":
        verts, faces = [], []
        for x in np.arange(-90.0, 91.0, 10.0):
            for y in (-4.0, 4.0):
                v, f = box([x - 0.2, y - 0.2, 0.0], [x + 0.2, y + 0.2, 4.0])
                faces.append(f + sum(len(a) for a in verts))
                verts.append(v)
        shapes = {"ground": quad([0, 0, 0], [100.0, 0, 0], [0, 10.0, 0]),
                  "posts": (np.vstack(verts), np.vstack(faces))}
        return shapes, ((-99.0, 0.0, 3.0), (-60.0, 0.0, 0.0), 60.0), \
            LightSpec("directional", direction=normalize([0.2, -0.5, -0.6]))
    if name == "terrain":
        from . import terrain
        verts, faces = terrain.mesh(p.stride)
        # a viewer 800 m above the south-west corner looking north-east across the fault, 27
        # degrees down; the sun 20 degrees above the horizon from the south-east
        eye = (-13000.0, -14000.0, 1600.0)
        return {"terrain": (verts, faces)}, (eye, (-8000.0, -9000.0, -2000.0), 60.0), \
            LightSpec("directional", direction=normalize([-0.664, 0.664, -0.342]))
    raise KeyError(name)


def _scale_light(light: LightSpec, s: float, offset=ORIGIN) -> LightSpec:
    """A light given relative to the scene: positions scaled by ``s``, then moved by ``offset``."""
    if light.position is None:
        return light
    from dataclasses import replace
    t = tuple(float(c) for c in offset)
    return replace(light, position=tuple(s * c + o for c, o in zip(light.position, t)),
                   target=None if light.target is None else tuple(s * c + o for c, o in zip(light.target, t)),
                   size=tuple(s * c for c in light.size))


# ---------------------------------------------------------------- loaded scenes

@dataclass
class SceneData:
    """A loaded scene: Mitsuba scene and sensor, shape names, own lights, bounds, and the config's scale and offset."""
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
    offset: tuple = ORIGIN         # added to the config's light positions after scaling (translate)
    camera_pose: object = None     # the camera's (position, target, up), float64 (built-ins and mesh files)
    checked: tuple = ()            # shapes the loader already checked (check_mesh), not checked again
    centre: object = None          # the exact frame's origin (dsm.scenes.exact_frame; float64 world), None: the world
    exact_scene: object = None     # the scene in that frame (None: ``scene``)

    @property
    def exact(self):
        """The Mitsuba scene the exact side (G-buffer, reference) is traced in."""
        return self.scene if self.exact_scene is None else self.exact_scene

    def centre_frame(self, shapes64: dict):
        """Trace the exact side in a frame centred on the scene when it sits far from the origin
        (:mod:`dsm.scenes.exact_frame`): ``shapes64`` the world scene's meshes by key, in float64."""
        centre = exact_frame.centre_for(self.bbox)
        if centre is None:
            return
        self.centre, self.exact_scene = centre, _moved_scene(shapes64, centre)
        ids = [sh.id() for sh in self.scene.shapes()]
        if ids != [sh.id() for sh in self.exact_scene.shapes()]:
            raise RuntimeError(f"scene {self.label!r}: the centred frame's shapes are not in the world's order")

    @property
    def diagonal(self) -> float:
        """The length of the scene's bounding-box diagonal (world units)."""
        return float(np.linalg.norm(self.bbox[1] - self.bbox[0]))

    def lights_for(self, specs) -> list:
        """The lights of the ``[[light]]`` specs that apply here: the scene's own, its emitters, or scaled."""
        out = []
        for spec in specs:
            if not spec.applies_to(self.label):
                continue
            if spec.type == "scene":
                out += self.own_lights
            elif spec.type == "area" and spec.shape == "emitter":
                from ..truth.area import emitter_lights
                out += emitter_lights(self.scene, spec)     # the scene's own luminaires, as they are
            else:
                out.append(_scale_light(spec, self.scale, self.offset))
        return out


def _moved_scene(shapes64: dict, centre: np.ndarray):
    """A Mitsuba scene of ``shapes64`` {key: (vertices (n, 3) float64 world, faces)} moved by
    minus ``centre`` in float64, then rounded to float32; the keys (and so the shapes' order)
    those of the world scene's dict."""
    import mitsuba as mi
    d = {"type": "scene"}
    for name, (v, f) in shapes64.items():
        d[name] = make_mesh(name, np.asarray(v, np.float64) - centre, f)
    return mi.load_dict(d, optimize=False)


def load(spec: SceneSpec, camera_resolution=None, camera=None) -> SceneData:
    """Load one scene with its camera at ``camera_resolution`` (width, height). None: an XML
    scene's own film size, else DEFAULT_CAMERA; given, an XML sensor is re-created at that width
    with its film's aspect ratio, transform and field of view. A scene that cannot be used raises
    ConfigError naming ``spec.source`` and the [[scene]] key (``spec.where``). ``camera``: the
    [camera] pose (a CameraSpec), overriding the scene's own (an XML sensor's too)."""
    import mitsuba as mi
    if spec.missing:
        raise ConfigError(_src(spec), f"{spec.where}.file", spec.missing)
    if spec.params is not None and spec.params.precision == "camera_relative":
        return _camera_relative(spec, camera_resolution, camera)
    if spec.builtin:
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
                                                 (fov or [40])[0], None, None), camera, s, p.translate, _src(spec))
        d["sensor"] = look_at_sensor(o, tg, up, fv, w, h, near,
                                     far if far is not None else far_bound(o, tg, allv.min(0), allv.max(0)),
                                     camera, _src(spec))
        scene = mi.load_dict(d, optimize=False)
        data = _finish(spec.label, scene, [_scale_light(light, s, p.translate)], s)
        data.offset = tuple(float(c) for c in p.translate)
        data.camera_pose = (np.asarray(o, float), np.asarray(tg, float), np.asarray(up, float))
        data.centre_frame({name: (np.asarray(v, float) * s + t, f) for name, (v, f) in shapes.items()})
    else:
        try:
            if spec.file.suffix.lower() == ".xml":
                data = _load_xml(spec, camera_resolution, camera)
            else:
                data = _load_mesh_file(spec, *(camera_resolution or DEFAULT_CAMERA), camera=camera)
        except ConfigError:
            raise
        except (RuntimeError, ValueError, OSError) as e:      # Mitsuba's loaders raise RuntimeError
            raise ConfigError(_src(spec), f"{spec.where}.file", f"cannot load {spec.file}: "
                              f"{_mitsuba_message(e, spec.file.suffix.lower() != '.xml')}") from None
    data.closed_override = spec.closed
    _check_loaded(spec, data)
    return data


def check(cfg, keep: bool = False):
    """Load every scene of ``cfg`` (absent optional files aside) before any work starts.

    The first scene that cannot be used raises its ConfigError, with the other scenes' problems
    in its ``more`` list (``dsm plan`` prints them all). Returns the loaded SceneData in config
    order (None for absent files) when ``keep``. Needs a Mitsuba variant (``env.use_variant``)."""
    loaded, errors, seen = [], [], set()
    for spec in cfg.scenes:
        sd = None
        if not spec.missing:
            try:
                sd = load(spec, cfg.camera_resolution, cfg.camera)
                _check_options(cfg, spec, sd)
            except ConfigError as e:
                if str(e) not in seen:          # a swept file that cannot be read says so once
                    seen.add(str(e))
                    errors.append(e)
        loaded.append(sd if keep else None)
    if errors:
        errors[0].more = errors[1:]
        raise errors[0]
    return loaded if keep else None


def _check_options(cfg, spec, sd):
    """ConfigError where a loaded scene cannot take the config's opt-in steps: contact shadows and
    distance-scaled schemes need a perspective camera, caster shrinking triangle meshes."""
    import mitsuba as mi
    need = ["contact"] if getattr(cfg, "contact", None) is not None else []
    need += [f"scheme {s.name}" for s in cfg.schemes if s.name == "distance_normal"][:1]
    if need and "x_fov" not in mi.traverse(sd.sensor):
        raise ConfigError(_src(spec), need[0].split()[0], f"{spec.where}: {need[0]} needs a perspective camera; the "
                          f"scene's sensor has no field of view ({type(sd.sensor).__name__})")
    if getattr(cfg, "shrink", None) is not None:
        flat = [sh.id() or str(i) for i, sh in enumerate(sd.scene.shapes()) if not sh.is_mesh()]
        if flat:
            raise ConfigError(_src(spec), "map.shrink", f"{spec.where}: shrinking moves mesh vertices and "
                              + (f"{flat[0]} is not a triangle mesh; remove map.shrink or give it as a mesh"
                                 if len(flat) == 1 else f"{', '.join(flat[:3])} are not triangle meshes; remove "
                                 "map.shrink or give them as meshes"))
        _check_shrink_fits(cfg.shrink, spec, sd)


def _check_shrink_fits(d: float, spec, sd):
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
            raise ConfigError(_src(spec), "map.shrink", f"{spec.where}: {d:g} is at least half the thinnest extent "
                              f"of the closed shape {name!r} ({thin:.3g} across): moved that far inward it turns "
                              f"inside out; give less than {thin / 2:.3g}")


def _src(spec) -> str:
    return spec.source or "<scene>"


def _mitsuba_message(e, mesh_file: bool = False) -> str:
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
    """Problems Mitsuba reports badly or not at all: an empty file, a mesh without faces, a file that is no PLY."""
    path, key = spec.file, f"{spec.where}.file"
    try:
        size = path.stat().st_size
        if size == 0:
            raise ConfigError(_src(spec), key, f"{path} is empty")
        suffix = path.suffix.lower()
        if suffix == ".obj":
            data = path.read_bytes()
            if re.search(rb"(?m)^[ \t]*f[ \t]", data) is None:
                raise ConfigError(_src(spec), key, f"{path} has no faces (no 'f' lines): dsm needs a triangle mesh")
            # a record cut short (a file truncated mid-line): Mitsuba would load the rest silently
            short = re.search(rb"(?m)^[ \t]*([vf])[ \t]+\S+(?:[ \t]+\S+)?[ \t]*\r?$", data)
            if short is not None:
                line = data.count(b"\n", 0, short.start()) + 1
                what = "vertex with fewer than 3 coordinates" if short.group(1) == b"v" else "face with fewer than 3 corners"
                raise ConfigError(_src(spec), key, f"{path}: line {line} is a {what} (a file cut short?)")
        elif suffix == ".ply":
            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
            if not head.startswith(b"ply"):
                raise ConfigError(_src(spec), key, f"{path} is not a PLY file (it does not start with 'ply')")
            end = head.find(b"end_header")
            if end < 0:
                raise ConfigError(_src(spec), key, f"{path}: the PLY header has no end_header")
            m = re.search(rb"element\s+face\s+(\d+)", head[:end])
            if m is None or int(m.group(1)) == 0:
                raise ConfigError(_src(spec), key, f"{path} has no faces (PLY element face: "
                                  f"{m.group(1).decode() if m else 'absent'}): dsm needs a triangle mesh")
            bad = ply_index_problem(path, head, end)
            if bad:
                raise ConfigError(_src(spec), key, f"{path}: {bad}")
    except OSError as e:
        raise ConfigError(_src(spec), key, f"cannot read {path}: {e.strerror or e}") from None


PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
PLY_ORDER = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}


def ply_index_problem(path: Path, head: bytes, end: int) -> str | None:
    """A PLY face index outside its vertices, in words (None: all in range, or left to Mitsuba)."""
    # Mitsuba reads such a face past its vertex buffer (a segfault, not an error); a truncated
    # file or a header this does not read (lists before the faces, mixed polygon sizes) Mitsuba
    # reports itself
    try:
        fmt, elements = _ply_header(head[:end])
        data = head.index(b"\n", end) + 1
        counts, faces = _ply_faces(path, data, fmt, elements)
    except (ValueError, KeyError, IndexError, StopIteration):
        return None
    n = counts.get("vertex", 0)
    if faces is None or faces.size == 0:
        return None
    lo, hi = int(faces.min()), int(faces.max())
    if lo >= 0 and hi < n:
        return None
    worst = hi if hi >= n else lo
    which = f"face {int(np.flatnonzero((faces == worst).any(axis=1))[0])}" if faces.ndim == 2 else "a face"
    return f"{which} refers to vertex {worst} of {n} (indices 0 to {n - 1}): the file is damaged"


def _ply_header(text: bytes):
    """(format, [(element, count, [(name, type) or (name, (count type, item type))])]) of a PLY header."""
    fmt, elements = None, []
    for line in text.decode("ascii", "replace").splitlines():
        w = line.split()
        if w[:1] == ["format"]:
            fmt = w[1]
        elif w[:1] == ["element"]:
            elements.append((w[1], int(w[2]), []))
        elif w[:2] == ["property", "list"]:
            elements[-1][2].append((w[4], (PLY_TYPES[w[2]], PLY_TYPES[w[3]])))
        elif w[:1] == ["property"]:
            elements[-1][2].append((w[2], PLY_TYPES[w[1]]))
    if fmt not in PLY_ORDER:
        raise ValueError(fmt)
    return fmt, elements


def _ply_faces(path: Path, offset: int, fmt: str, elements):
    """({element: count}, the face element's vertex indices: an (n, k) array, or a flat one)."""
    counts = {name: n for name, n, _ in elements}
    if fmt == "ascii":
        return counts, _ply_ascii_faces(path.read_bytes()[offset:], elements)
    order = PLY_ORDER[fmt]
    buf = np.memmap(path, np.uint8, mode="r")
    for name, n, props in elements:
        if name == "face":
            return counts, _ply_binary_faces(buf, offset, n, props, order)
        if any(isinstance(t, tuple) for _, t in props):
            raise ValueError("a list before the faces")      # rare: Mitsuba's own checks only
        offset += n * sum(np.dtype(t).itemsize for _, t in props)
    return counts, None


def _ply_binary_faces(buf, offset, n, props, order):
    # every face with the first face's corner count (triangles, or quads): one strided read
    first = offset
    fields = []
    for name, t in props:
        if isinstance(t, tuple):
            k = int(np.frombuffer(buf, order + t[0], 1, first)[0])
            fields += [(name + "#n", order + t[0]), (name, order + t[1], (k,))]
            first += np.dtype(t[0]).itemsize
        else:
            fields.append((name, order + t))
            first += np.dtype(t).itemsize
    rec = np.frombuffer(buf, np.dtype(fields), n, offset)      # ValueError when truncated
    lists = [name for name, t in props if isinstance(t, tuple)]
    if not all((rec[f + "#n"] == rec[f + "#n"][0]).all() for f in lists):
        raise ValueError("faces of several sizes")             # Mitsuba's own checks only
    key = "vertex_indices" if "vertex_indices" in lists else lists[0]
    return rec[key].astype(np.int64)


def _ply_ascii_faces(body: bytes, elements):
    rows = iter(l.split() for l in body.splitlines() if l.strip())
    for name, n, props in elements:
        if name != "face":
            for _ in range(n):
                next(rows)                                     # StopIteration: truncated
            continue
        out = []
        for _ in range(n):
            w, i = next(rows), 0
            for pname, t in props:
                k = int(w[i]) + 1 if isinstance(t, tuple) else 1
                if isinstance(t, tuple) and pname in ("vertex_indices", "vertex_index"):
                    out += [int(x) for x in w[i + 1:i + k]]
                i += k
        return np.asarray(out, np.int64)
    return None


def _camera_relative(spec, camera_resolution, camera):
    """The scene as an engine rendering relative to its camera holds it: ``translate`` less the
    camera's world position (float64) before anything is rounded to float32, so the camera sits at
    the origin; the config's lights and camera follow (they move with ``translate``). The camera's
    position moves with ``translate``, so it is found on the scene at the origin (one load of it
    first, where float32 holds it whatever the offset) plus the offset."""
    from dataclasses import replace
    t = np.asarray(spec.params.translate, float)
    at_origin = replace(spec.params, precision="world", translate=ORIGIN)
    origin = load(replace(spec, params=at_origin), camera_resolution, camera)
    cam = origin.camera_pose[0] + t
    shift = tuple(float(c) for c in t - cam)
    lo, hi = (np.asarray(c, float) for c in origin.bbox)
    _check_held(float(np.max(hi - lo)), np.maximum(np.abs(lo + shift), np.abs(hi + shift)), _src(spec),
                "camera.position" if camera is not None and camera.position is not None else f"{spec.where}.precision",
                "from its camera (camera_relative)", "the scene's distance to the camera")
    data = load(replace(spec, params=replace(at_origin, translate=shift)), camera_resolution, camera)
    data.notes.append(f"camera_relative: positions relative to the camera at "
                      f"({', '.join(f'{c:.9g}' for c in cam)}) in world coordinates")
    return data


def check_mesh(shape, name: str, spec):
    """ConfigError naming the [[scene]] key where a mesh has no triangles, non-finite positions,
    faces beyond its vertices or triangles whose float32 normals overflow or underflow."""
    src = _src(spec)
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
    c = _cross_lengths(v, f)
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


def _check_loaded(spec, data):
    """What a loaded scene must hold: shapes, triangles, finite positions, float32-safe normals."""
    src = _src(spec)
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
                          data.shape_names)


def _finish(label, scene, own_lights, scale, notes=()):
    bb = scene.bbox()
    bbox = (np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel())
    names = [sh.id() or f"shape{i}" for i, sh in enumerate(scene.shapes())]
    if not scene.sensors():
        raise ValueError(f"scene {label!r} has no sensor")
    return SceneData(label, scene, scene.sensors()[0], names, list(own_lights), bbox, scale, list(notes))


def _check_emitters(spec, lights):
    """ConfigError naming the file for an emitter at a position, along a direction or with a
    cutoff that is not finite (every receiver read as backfacing: the case came out empty)."""
    for i, light in enumerate(lights):
        vals = {"position": light.position, "direction": light.direction,
                "cutoff_angle": (light.cutoff,)}        # a spot's; the others keep the finite default
        for name, v in vals.items():
            if v is not None and not all(math.isfinite(c) for c in v):
                raise ConfigError(_src(spec), f"{spec.where}.file", f"{spec.file}: emitter {i} ({light.type}) has a "
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


def from_mitsuba(scene, label: str = "scene") -> "SceneData":
    """SceneData of an already loaded Mitsuba scene (the integrator plugins' entry)."""
    lights, notes = lights_of(scene)
    return _finish(label, scene, lights, 1.0, notes)


def _load_xml(spec, camera_resolution, camera=None):
    import mitsuba as mi
    _precheck_file(spec)
    scene = mi.load_file(str(spec.file), optimize=False)
    if not scene.sensors():
        raise ConfigError(_src(spec), f"{spec.where}.file", f"{spec.file} has no <sensor>: dsm takes the camera "
                          "from an XML scene's first sensor; add one")
    lights, notes = lights_of(scene)
    _check_emitters(spec, lights)
    if not lights:
        lights = [default_light(scene)]
        notes.append(f"no point, spot or directional emitter: dsm added a default {describe_light(lights[0])}")
    sensor = scene.sensors()[0]
    data = _finish(spec.label, scene, lights, 1.0, notes)
    if camera_resolution is not None:
        # [camera] resolution: the sensor re-created at that width, with its film's aspect ratio,
        # transform and field of view; without it the XML's own sensor and film are the camera
        film = sensor.film().size()
        width = int(camera_resolution[0])
        data.sensor = _resized_sensor(sensor, width, max(1, round(width * film[1] / film[0])))
    if camera is not None:
        data.sensor = _reposed_sensor(data.sensor, camera, data.bbox, _src(spec))
    return data


def _reposed_sensor(sensor, camera, bbox, source="<config>"):
    """An XML scene's sensor with the [camera] pose: its film (size) kept, the keys given replaced."""
    import mitsuba as mi
    params = mi.traverse(sensor)
    m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    o = m[:3, 3]
    fwd, up = m[:3, 2], m[:3, 1]
    near = float(np.ravel(params["near_clip"])[0]) if "near_clip" in params else None
    far = float(np.ravel(params["far_clip"])[0]) if "far_clip" in params else None
    fov = float(params["x_fov"][0]) if "x_fov" in params else 40.0
    # the XML's target: the point of its view axis nearest the scene's centre (a new position looks there)
    centre = 0.5 * (np.asarray(bbox[0], float) + np.asarray(bbox[1], float))
    reach = float((centre - o) @ fwd)
    reach = reach if reach > 0 else float(np.linalg.norm(np.asarray(bbox[1], float) - np.asarray(bbox[0], float)))
    o2, t2, up2, fov2, near2, far2 = posed_camera((o, o + fwd * reach, up, fov, near, far), camera, source=source)
    if camera.far is None and (camera.position is not None or camera.target is not None):
        far2 = far_bound(o2, t2, *bbox)
    W, H = (int(x) for x in sensor.film().size())
    d = look_at_sensor(o2, t2, up2, fov2, W, H, near2 if near2 is not None else None, far2, camera, source)
    d["fov_axis"] = "x"
    return mi.load_dict(d)


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


def _load_mesh_file(spec, width, height, camera=None):
    import mitsuba as mi
    p = spec.params
    _precheck_file(spec)
    up = np.eye(3)["xyz".index(p.up)]
    to_world = mi.ScalarTransform4f().translate([float(c) for c in p.translate]).scale(p.scale)
    mesh = mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file), "to_world": to_world})
    check_mesh(mesh, "mesh", spec)      # before the camera is posed from its bounds (a 1e-20 mesh has none)
    bb = mesh.bbox()
    lo, hi = np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel()
    mesh64 = None
    if exact_frame.centre_for((lo, hi)) is not None:
        # far from the origin: the file's vertices scaled in float32 as at the origin, then moved in
        # float64, for the exact frame and for the ground and camera both frames share
        local = mi.load_dict({"type": spec.file.suffix.lower()[1:], "filename": str(spec.file),
                              "to_world": mi.ScalarTransform4f().scale(p.scale)})
        mesh64 = (np.asarray(local.vertex_positions_buffer(), np.float64).reshape(-1, 3) + np.asarray(p.translate, float),
                  np.asarray(local.faces_buffer(), np.int64).reshape(-1, 3))
        lo, hi = mesh64[0].min(0), mesh64[0].max(0)
    center, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    if p.precision == "world":       # the mesh and its ground (3 diagonals across) rounded at the offset
        _check_held(max(float(np.max(hi - lo)), 3 * size if p.ground == "yes" else 0.0), p.translate, _src(spec),
                    f"{spec.where}.translate", "from the origin")
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
                                         _src(spec))
    lo_all, hi_all = (lo, hi) if p.ground != "yes" else (np.minimum(lo, center - size * 1.5), np.maximum(hi, center + size * 1.5))
    d["sensor"] = look_at_sensor(o, tg, upv, fv, width, height, near,
                                 far if far is not None else far_bound(o, tg, lo_all, hi_all), camera, _src(spec))
    scene = mi.load_dict(d, optimize=False)
    light = LightSpec("directional", direction=normalize(-up * 1.0 - a * 0.3 + b * 0.2))
    data = _finish(spec.label, scene, [light], p.scale)
    data.offset = tuple(float(c) for c in p.translate)
    data.camera_pose = (np.asarray(o, float), np.asarray(tg, float), np.asarray(upv, float))
    data.checked = ("mesh",)              # checked before the camera was posed
    if mesh64 is not None:
        data.centre_frame({"mesh": mesh64, **({"ground": (v, f)} if "ground" in d else {})})
    return data
