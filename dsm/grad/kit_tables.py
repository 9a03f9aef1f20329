"""dsm grad's scene, light, map and bias from the kit's own tables: ``[[scene]]``, ``[[light]]``,
``[map]`` and ``[[scheme]]``, read into the GradSpec's fields.

- ``[[scene]]``: one occluder built-in (:data:`SCENES`, the one table of names) with ``size`` and
  ``height`` (world), ``box_height`` for the box, ``mesh`` (a PLY or OBJ file) for a mesh.
- ``[[light]]``: one light, read by the light registry's own parser (:func:`dsm.lights.get`), then
  held to what dsm grad differentiates: a spot straight down from ``[0, 0, H]`` (gradient's
  "point"), a directional light whose direction lies in the x-z plane (its tilt from the vertical
  toward +x is the angle), a square area light facing down from ``[0, 0, H]``.
- ``[map]``: ``resolution``, ``kind`` (depth, then every pre-filtered kind), ``filter`` (the depth
  map's), ``blur`` (the moment kinds'), ``antialias`` (Worchel & Alexa 2023's edge treatment: dsm
  grad's own key). Lists sweep; the techniques are kinds x filters or blurs x antialias, in order.
- ``[[scheme]]``: the depth techniques' bias, a ``constant`` scheme in world units.

Whatever dsm grad would ignore is refused in one line, before any work.
"""
from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

from .. import lights, schemes
from ..config.read import parse_scheme
from ..core.types import ConfigError, as_list, check_keys, choice, number
from ..scenes.params import OccluderMeshParams
from ..scenes.spec import resolve_path
from . import support
from .technique import MOMENT_TECHNIQUES, Technique

# [[scene]] builtin -> GradSpec.scene: the one place the names live
SCENES = {"occluder_plate": "plate", "occluder_box": "box", "occluder_mesh": "mesh"}
SCENE_KEYS = {"plate": ("builtin", "size", "height"), "box": ("builtin", "size", "height", "box_height"),
              "mesh": ("builtin", "size", "height", "mesh")}
MESH_SUFFIXES = next(f.metadata["path"] for f in fields(OccluderMeshParams) if f.name == "mesh")
MAP_KEYS = ("resolution", "kind", "filter", "blur", "antialias")
KINDS = ("depth",) + MOMENT_TECHNIQUES
SCHEMES = ("constant",)          # the depth techniques' bias dsm grad differentiates through
MAX_BLUR = 31
MAX_RESOLUTION = 4096
MIN_ANGLE, MAX_ANGLE = -60.0, 60.0   # the directional light's tilt (degrees): beyond it the ground grazes
ANGLE_DIGITS = 9                 # a tilt from a direction, in degrees: float64's rounding (1e-14) dropped
# [[light]] keys the registry reads and dsm grad would ignore -> why
LIGHT_IGNORED = {
    "cutoff": "dsm grad fits the spot's cone to the image window itself",
    "scenes": "dsm grad has one scene",
    "min_samples": "dsm grad's area-light truth takes gradient.light_samples",
    "max_samples": "dsm grad's area-light truth takes gradient.light_samples",
    "tolerance": "dsm grad's area-light truth takes gradient.light_samples",
    "confidence": "dsm grad's area-light truth takes gradient.light_samples",
    "replicates": "dsm grad's area-light truth takes gradient.light_samples",
}
DOWN = (0.0, 0.0, -1.0)


def one_table(raw: dict, key: str, source: str) -> dict:
    """The one ``[[key]]`` table of ``raw``; a ConfigError where there is none or more than one."""
    tables = raw.get(key)
    if isinstance(tables, dict):
        tables = [tables]
    if not isinstance(tables, list) or not tables or not all(isinstance(t, dict) for t in tables):
        got = "none" if tables is None else repr(tables)
        raise ConfigError(source, key, f"dsm grad needs one [[{key}]] table, got {got}")
    if len(tables) > 1:
        raise ConfigError(source, f"{key}[1]", f"dsm grad takes exactly one [[{key}]], got {len(tables)}: "
                          "differentiate each in its own config")
    return tables[0]


def read_scene(raw: dict, source: str) -> dict:
    """GradSpec's scene fields (scene, mesh, occluder_size, occluder_height, box_height) of the [[scene]]."""
    t = one_table(raw, "scene", source)
    name = choice(t.get("builtin"), source, "scene[0].builtin", tuple(SCENES))
    scene = SCENES[name]
    for key, owner in (("box_height", "occluder_box"), ("mesh", "occluder_mesh")):
        if key in t and name != owner:
            raise ConfigError(source, f"scene[0].{key}", f"is read only with builtin = \"{owner}\", not {name!r}")
    check_keys(t, SCENE_KEYS[scene], source, "scene[0]")
    kw = {"scene": scene}
    for key, field in (("size", "occluder_size"), ("height", "occluder_height"), ("box_height", "box_height")):
        if key in t:
            kw[field] = number(t[key], source, f"scene[0].{key}", positive=True)
    kw["mesh"] = mesh_path(t, source) if scene == "mesh" else ""
    return kw


def mesh_path(t: dict, source: str) -> str:
    """The occluder_mesh's file (relative to the config's folder), checked before any work."""
    raw = t.get("mesh")
    if not isinstance(raw, str) or not raw:
        raise ConfigError(source, "scene[0].mesh", f"occluder_mesh needs a PLY or OBJ file, got {raw!r}")
    return str(resolve_path(raw, MESH_SUFFIXES, source, "scene[0].mesh", Path(source).parent).resolve())


def read_light(raw: dict, source: str) -> dict:
    """GradSpec's light fields (light, light_height, light_angle, light_size) of the [[light]], read by the
    light registry's parser and held to the lights dsm grad differentiates."""
    t = one_table(raw, "light", source)
    kind = t.get("type")
    if kind in support.LIGHTS_WITHOUT:
        raise ConfigError(source, "light[0].type", f"{kind!r} has no gradient: {support.LIGHTS_WITHOUT[kind]}",
                          tuple(support.LIGHTS))
    kind = choice(kind, source, "light[0].type", tuple(support.LIGHTS))
    for key, why in LIGHT_IGNORED.items():
        if key in t:
            raise ConfigError(source, f"light[0].{key}", f"dsm grad would ignore it: {why}; remove it")
    module = lights.get(kind)
    light = module.parse(t, source, "light[0]")
    if not module.POSITIONAL:                 # a direction, no place: its tilt is the parameter
        return {"light": support.LIGHTS[kind], "light_angle": tilt(light.direction, source)}
    height = above_origin(light.position, source)
    kw = {"light": support.LIGHTS[kind], "light_height": height}
    if light.target is not None and not (light.target[0] == light.target[1] == 0.0 and light.target[2] < height):
        raise ConfigError(source, "light[0].target", f"dsm grad's spot looks straight down: give a target below "
                          f"it on the z axis, e.g. [0, 0, 0], or direction = [0, 0, -1]; got {list(light.target)}")
    if light.direction is not None and tuple(light.direction) != DOWN:
        raise ConfigError(source, "light[0].direction", f"dsm grad's {kind} light faces straight down "
                          f"(valid: [0, 0, -1]); got {list(light.direction)}")
    if module.SOFT:                           # a surface: its square's side
        kw["light_size"] = square_side(light, source)
    return kw


def above_origin(position, source: str) -> float:
    """The height of a light at ``[0, 0, H]`` (light_x, a parameter, moves it sideways)."""
    x, y, z = position
    if x != 0.0 or y != 0.0 or not z > 0.0:
        raise ConfigError(source, "light[0].position", f"dsm grad's light sits straight above the origin, "
                          f"[0, 0, H] with H > 0 (the parameter light_x moves it sideways); got {list(position)}")
    return float(z)


def tilt(direction, source: str) -> float:
    """A directional light's tilt from the vertical toward +x (degrees) from its travel ``direction``."""
    dx, dy, dz = direction
    if dy != 0.0 or not dz < 0.0:
        raise ConfigError(source, "light[0].direction", f"dsm grad's directional light travels down in the x-z "
                          f"plane: [sin a, 0, -cos a] for a tilt a toward +x (no y component); got {list(direction)}")
    angle = round(math.degrees(math.atan2(dx, -dz)), ANGLE_DIGITS)
    if not MIN_ANGLE <= angle <= MAX_ANGLE:
        raise ConfigError(source, "light[0].direction", f"tilts {angle:g} degrees from the vertical (valid: "
                          f"{MIN_ANGLE:g} to {MAX_ANGLE:g} degrees, [sin a, 0, -cos a])")
    return angle


def square_side(light, source: str) -> float:
    """The side of a square area light (``shape = "rectangle"``, one ``size`` or [s, s])."""
    if light.shape != "rectangle":
        raise ConfigError(source, "light[0].shape", f"dsm grad's area light is a square: got {light.shape!r}",
                          ("rectangle",))
    if len(set(light.size)) != 1:
        raise ConfigError(source, "light[0].size", f"dsm grad's area light is a square: give one side, got "
                          f"{list(light.size)}")
    return float(light.size[0])


def read_map(raw: dict, source: str) -> dict:
    """GradSpec's map_resolution and techniques of the ``[map]`` table (the kit's defaults where not given:
    resolution 512, kind depth, filter nearest, blur 1, antialias false)."""
    m = raw.get("map", {})
    if not isinstance(m, dict):
        raise ConfigError(source, "map", f"expected a table, got {m!r}")
    check_keys(m, MAP_KEYS, source, "map")
    res = m.get("resolution", 512)
    if isinstance(res, list):
        raise ConfigError(source, "map.resolution", f"dsm grad takes one map resolution, got {res!r}")
    kw = {"map_resolution": number(res, source, "map.resolution", integer=True, minimum=8, maximum=MAX_RESOLUTION)}
    kinds = listed(m, "kind", "depth", source, KINDS)
    if "depth" not in kinds and "filter" in m:
        raise ConfigError(source, "map.filter", "a filter is the depth map's and map.kind names no depth", KINDS)
    filters = listed(m, "filter", "nearest", source, support.FILTERS, support.FILTERS_WITHOUT)
    if not set(kinds) & set(MOMENT_TECHNIQUES) and "blur" in m:
        raise ConfigError(source, "map.blur", "a blur is a pre-filtered map's and map.kind names none",
                          MOMENT_TECHNIQUES)
    blurs = [number(b, source, "map.blur", integer=True, minimum=1, maximum=MAX_BLUR)
             for b in listed(m, "blur", 1, source)]
    if any(w % 2 == 0 for w in blurs):
        raise ConfigError(source, "map.blur", f"a blur width is odd (centred on the texel), got {blurs}")
    aas = listed(m, "antialias", False, source)
    if any(not isinstance(a, bool) for a in aas):
        raise ConfigError(source, "map.antialias", f"expected false, true or [false, true], got {m['antialias']!r}")
    names = [n for k in kinds for n in (filters if k == "depth" else [k])]
    kw["techniques"] = tuple(Technique(n, int(w), a) for n in names
                             for w in (blurs if n in MOMENT_TECHNIQUES else [1]) for a in aas)
    return kw


def listed(m: dict, key: str, default, source: str, choices=(), without=None) -> list:
    """``[map] key`` as a non-empty list of distinct values (each one of ``choices`` where given; a kit
    choice dsm grad does not differentiate refused with its reason from ``without``)."""
    values = as_list(m.get(key, default))
    if not values:
        raise ConfigError(source, f"map.{key}", "empty list", choices)
    for v in values:
        if without and v in without:
            raise ConfigError(source, f"map.{key}", f"{v!r} has no gradient: {without[v]}", choices)
        if choices:
            choice(v, source, f"map.{key}", choices)
    if len(set(map(repr, values))) != len(values):
        raise ConfigError(source, f"map.{key}", f"a value is given twice: give each once, got {values!r}")
    return values


def read_scheme(raw: dict, source: str, techniques: tuple) -> dict:
    """GradSpec's bias (world) of the [[scheme]] (a constant scheme): required where a technique reads the
    depth map, refused where none does (as ``dsm run`` does)."""
    depth = any(t.name not in MOMENT_TECHNIQUES for t in techniques)
    if "scheme" not in raw:
        if depth:
            raise ConfigError(source, "scheme", "the depth map's techniques need a [[scheme]] for their bias, e.g. "
                              "name = \"constant\", bias = 0.02", SCHEMES)
        return {}
    if not depth:
        raise ConfigError(source, "scheme", "[[scheme]] tables are the depth map's and map.kind does not name depth; "
                          "add depth to map.kind or remove them", KINDS)
    t = one_table(raw, "scheme", source)
    if t.get("name") not in SCHEMES:
        raise ConfigError(source, "scheme[0].name", f"dsm grad differentiates the depth map's tests with a constant "
                          f"bias only, got {t.get('name')!r}", SCHEMES)
    if "bias" not in t:
        raise ConfigError(source, "scheme[0].bias", "dsm grad needs the constant scheme's bias in world units, "
                          "e.g. bias = 0.02")
    specs = parse_scheme(t, source, "scheme[0]", schemes.ALL, schemes.PRESETS)
    if len(specs) != 1:
        raise ConfigError(source, "scheme[0].bias", f"dsm grad takes one bias, got {len(specs)}")
    bias = specs[0].params.bias
    if bias.unit != "world":
        raise ConfigError(source, "scheme[0].bias", f"dsm grad's bias is in world units (a number), got "
                          f"\"{bias.value:g} {bias.unit}\"")
    return {"bias": float(bias.value)}
