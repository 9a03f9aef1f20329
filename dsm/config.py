"""Experiment configs: TOML read once into frozen, validated dataclasses.

Everything is checked before any work starts. A mistake raises :class:`ConfigError`, whose
message names the file, the key and the valid choices. Lists sweep: every list-valued scheme
parameter, scene parameter or map option multiplies the cases (see :func:`expand`).
"""
from __future__ import annotations

import dataclasses
import itertools
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

LENGTH_UNITS = ("world", "texel", "range")
FILTERS = ("nearest", "pcf_bilinear", "pcf_jitter4x4")
FORMATS = ("float32", "unorm16", "unorm24", "ndc24")
POINT_VIEWS = ("paraboloid", "dual_paraboloid", "cube")
LIGHT_TYPES = ("scene", "directional", "spot", "point")
# vectorized Dr.Jit variants only: the kit's code runs on wide arrays (scalar_rgb cannot run it)
VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")


class ConfigError(ValueError):
    """A config mistake, reported before any work starts."""

    def __init__(self, source: str, key: str, problem: str, choices=None):
        self.source, self.key, self.problem = source, key, problem
        self.choices = tuple(choices) if choices else ()
        msg = f"{source}: {key}: {problem}"
        if self.choices:
            msg += f" (valid: {', '.join(map(str, self.choices))})"
        super().__init__(msg)
        self.more = []          # further problems of the same kind (scenes.check gathers every scene's)


class NothingToRun(ConfigError):
    """A valid config whose every scene is an absent optional file: the run would compute nothing."""


# ---------------------------------------------------------------- lengths

@dataclass(frozen=True)
class Length:
    """A length parameter: a world-space number, ``"k texel"`` or ``"k range"``.

    ``texel`` is the world width of one texel of the map at the receiver (constant for an
    orthographic view, growing with distance for a perspective one); ``range`` is a fraction
    of the view's depth range (far - near), the unit of hardware depth-bias constants.
    """
    value: float
    unit: str = "world"

    @staticmethod
    def parse(raw: Any, source: str = "<config>", key: str = "length") -> "Length":
        if isinstance(raw, Length):
            return raw
        if isinstance(raw, bool):
            raise ConfigError(source, key, f"expected a number or a string like \"2 texel\", got {raw!r}")
        if isinstance(raw, (int, float)):
            value, unit = float(raw), "world"
        elif isinstance(raw, str):
            parts = raw.split()
            if len(parts) != 2:
                raise ConfigError(source, key, f"cannot read length {raw!r}; write a number or \"<k> <unit>\"",
                                  LENGTH_UNITS)
            try:
                value = float(parts[0])
            except ValueError:
                raise ConfigError(source, key, f"{parts[0]!r} in {raw!r} is not a number") from None
            unit = parts[1].rstrip("s") if parts[1] not in LENGTH_UNITS else parts[1]
            if unit not in LENGTH_UNITS:
                raise ConfigError(source, key, f"unknown unit {parts[1]!r} in {raw!r}", LENGTH_UNITS)
        else:
            raise ConfigError(source, key, f"expected a number or a string like \"2 texel\", got {type(raw).__name__}")
        if not math.isfinite(value):
            raise ConfigError(source, key, f"length {raw!r} is not finite")
        return Length(value, unit)

    def __str__(self) -> str:
        v = f"{self.value:g}"
        return v if self.unit == "world" else f"{v} {self.unit}"


# ---------------------------------------------------------------- value checks

def _number(raw, source, key, *, integer=False, positive=False, minimum=None, maximum=None):
    if isinstance(raw, bool) or not isinstance(raw, (int, float)) or (integer and not isinstance(raw, int)):
        raise ConfigError(source, key, f"expected {'an integer' if integer else 'a number'}, got {raw!r}")
    if not math.isfinite(raw):
        raise ConfigError(source, key, f"{raw!r} is not finite")
    if positive and raw <= 0:
        raise ConfigError(source, key, f"must be > 0, got {raw!r}")
    if minimum is not None and raw < minimum:
        raise ConfigError(source, key, f"must be >= {minimum}, got {raw!r}")
    if maximum is not None and raw > maximum:
        raise ConfigError(source, key, f"must be <= {maximum}, got {raw!r}")
    return int(raw) if integer else float(raw)


def _choice(raw, source, key, choices):
    if not isinstance(raw, str) or raw not in choices:
        raise ConfigError(source, key, f"unknown value {raw!r}", choices)
    return raw


def _vec3(raw, source, key, nonzero=False):
    if not isinstance(raw, list) or len(raw) != 3:
        raise ConfigError(source, key, f"expected a list of three numbers, got {raw!r}")
    v = tuple(_number(x, source, key) for x in raw)
    if nonzero and not any(v):
        raise ConfigError(source, key, "direction must not be zero")
    return v


def _as_list(raw):
    return raw if isinstance(raw, list) else [raw]


def _check_keys(table: dict, allowed, source: str, where: str):
    for k in table:
        if k not in allowed:
            raise ConfigError(source, f"{where}.{k}" if where else k, "unknown key", sorted(allowed))


def coerce_field(f: dataclasses.Field, raw, source: str, key: str):
    """Convert one raw TOML value to a parameter dataclass field's type (Length, float, int, str, or
    a ``tuple`` of three numbers). ``metadata["min"]`` bounds numbers and Lengths (their value, in
    any unit: an upper limit or an offset below 0 has no meaning)."""
    if f.type in ("Length", Length):
        value = Length.parse(raw, source, key)
        lo = f.metadata.get("min")
        if lo is not None and value.value < lo:
            raise ConfigError(source, key, f"must be >= {lo:g}, got {raw!r}")
        return value
    if f.type in ("tuple", tuple):
        return _vec3(raw, source, key)
    if f.type in ("float", float):
        return _number(raw, source, key, minimum=f.metadata.get("min"))
    if f.type in ("int", int):
        return _number(raw, source, key, integer=True, minimum=f.metadata.get("min"))
    if f.type in ("str", str):
        return _choice(raw, source, key, f.metadata["choices"])
    raise TypeError(f"unsupported parameter type {f.type!r}")


def sweep_params(cls, table: dict, source: str, where: str, skip=()) -> list:
    """Expand a table of (possibly list-valued) parameters into instances of ``cls``."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    _check_keys({k: v for k, v in table.items() if k not in skip}, fields, source, where)
    names, options = [], []
    for k, raw in table.items():
        if k in skip:
            continue
        if fields[k].type in ("tuple", tuple):
            # a vector: [x, y, z] is one value, a list of vectors sweeps
            values = raw if isinstance(raw, list) and raw and all(isinstance(x, list) for x in raw) else [raw]
        else:
            values = _as_list(raw)
        if not values:
            raise ConfigError(source, f"{where}.{k}", "empty list")
        names.append(k)
        options.append([coerce_field(fields[k], v, source, f"{where}.{k}") for v in values])
    return [cls(**dict(zip(names, combo))) for combo in itertools.product(*options)]


# ---------------------------------------------------------------- config tables

@dataclass(frozen=True)
class SceneSpec:
    """One scene: a built-in with its parameters, or a file (Mitsuba XML, OBJ, PLY)."""
    builtin: str | None = None
    file: Path | None = None
    params: Any = None          # builtin: its parameter dataclass; file: FileSceneParams
    label: str = ""
    closed: tuple = ()          # (shape name, closed) overrides of detected closedness
    missing: str = ""           # an optional file that is absent: the run records it as skipped
    source: str = field(default="", compare=False)     # the config file, for errors found on loading
    where: str = field(default="scene", compare=False)  # its [[scene]] key, e.g. "scene[2]"


@dataclass(frozen=True)
class LightSpec:
    """A light. ``scene``: the scene's own lights (built-in default or XML emitters)."""
    type: str
    direction: tuple | None = None
    position: tuple | None = None
    target: tuple | None = None
    cutoff: float = 30.0        # spot half angle in degrees
    label: str = ""


@dataclass(frozen=True)
class MapSpec:
    resolution: tuple = (512,)
    filter: tuple = ("nearest",)
    format: tuple = ("float32",)
    view: tuple = ("dual_paraboloid",)
    texels: tuple = ()          # equal-memory sweeps: total texels per view, R = round(sqrt(texels / faces))

    def resolutions_for(self, faces: int) -> tuple:
        """Per-face resolutions of a view with ``faces`` faces (from ``texels`` when given)."""
        if not self.texels:
            return self.resolution
        return tuple(max(1, round((t / faces) ** 0.5)) for t in self.texels)


@dataclass(frozen=True)
class SchemeSpec:
    name: str
    params: Any                 # the scheme's frozen parameter dataclass
    preset: str | None = None

    @property
    def label(self) -> str:
        from .schemes import describe_params
        return describe_params(self.params)


@dataclass(frozen=True)
class Config:
    name: str
    source: str
    seed: int = 7
    variant: str | None = None
    camera_resolution: tuple | None = None   # None: an XML scene's own film, else DEFAULT_CAMERA
    scenes: tuple = ()
    lights: tuple = ()
    map: MapSpec = field(default_factory=MapSpec)
    schemes: tuple = ()
    timing_repeats: int = 3
    memory_budget_mb: float | None = None   # None: a quarter of this machine's memory
    raw: dict = field(default_factory=dict, compare=False)


TOP_KEYS = ("experiment", "camera", "scene", "light", "map", "scheme", "timing", "memory")
DEFAULT_CAMERA = (256, 256)     # built-ins and meshes without [camera] resolution


def load(path) -> Config:
    path = Path(path)
    source = str(path)
    if path.is_dir():
        raise ConfigError(source, "file", "is a folder, not a config file")
    if not path.is_file():
        raise ConfigError(source, "file", "no such config file")
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(source, "toml", f"not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(source, "file", f"not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}): "
                          "TOML files are UTF-8; save it as UTF-8") from None
    except OSError as e:
        raise ConfigError(source, "file", f"cannot read it: {e.strerror or e}") from None
    return parse(raw, source, base=path.parent)


def coerce(obj, source: str = "<dict>") -> Config:
    """A Config from what ``dsm.run`` accepts: a Config, a dict of config tables, or a path (str or
    os.PathLike) to a TOML file. Anything else is a TypeError with one line saying what is accepted;
    a mistake inside is a ConfigError."""
    if isinstance(obj, Config):
        return obj
    if isinstance(obj, dict):
        return parse(obj, source)
    if isinstance(obj, (str, os.PathLike)):
        return load(obj)
    raise TypeError(f"dsm.run: config must be a dsm Config, a dict of config tables or a path to a TOML file, "
                    f"not {type(obj).__name__} ({obj!r:.60})")


def absent_files(cfg: Config) -> list:
    """Files of the config's optional scenes that are absent (each once, in config order)."""
    out = []
    for s in cfg.scenes:
        if s.missing and s.file not in out:
            out.append(s.file)
    return out


def check_runnable(cfg: Config):
    """Raise NothingToRun when every scene of the config is an absent optional file."""
    if cfg.scenes and all(s.missing for s in cfg.scenes):
        files = absent_files(cfg)
        where = sorted({str(f.parent) for f in files})
        raise NothingToRun(cfg.source, "scene", "nothing to run: every scene is an absent optional file ("
                           + ", ".join(f.name for f in files) + f" in {', '.join(where)}); "
                           "README.md (Credits: test meshes in ../shared/meshes) says where to get them")


def _plain_name(name, source):
    if not isinstance(name, str) or not name:
        raise ConfigError(source, "experiment.name", "expected a non-empty string")
    if ("/" in name or "\\" in name or name in (".", "..") or any(ord(c) < 32 for c in name)
            or os.sep in name or (os.altsep and os.altsep in name)):
        raise ConfigError(source, "experiment.name", f"{name!r} must be a plain file name (it names the results "
                          "folder under runs/): no '/', '\\', '..' or control characters")
    return name


def parse(raw: dict, source: str = "<config>", base: Path | None = None) -> Config:
    from . import scenes as scenes_mod
    from .schemes import REGISTRY, PRESETS

    base = Path(base or ".")
    _check_keys(raw, TOP_KEYS, source, "")

    exp = _table(raw, "experiment", source)
    _check_keys(exp, ("name", "seed", "variant"), source, "experiment")
    name = _plain_name(exp.get("name", Path(source).stem if not source.startswith("<") else "experiment"), source)
    seed = _number(exp.get("seed", 7), source, "experiment.seed", integer=True)
    variant = exp.get("variant")
    if variant is not None:
        _choice(variant, source, "experiment.variant", VARIANTS)

    cam = _table(raw, "camera", source)
    _check_keys(cam, ("resolution",), source, "camera")
    camera_resolution = None
    if "resolution" in cam:
        res = cam["resolution"]
        if isinstance(res, int) and not isinstance(res, bool):
            res = [res, res]
        if not isinstance(res, list) or len(res) != 2:
            raise ConfigError(source, "camera.resolution", f"expected [width, height], got {res!r}")
        camera_resolution = tuple(_number(x, source, "camera.resolution", integer=True, minimum=1, maximum=16384)
                                  for x in res)

    scene_tables = _array_of_tables(raw, "scene", source)
    if not scene_tables:
        raise ConfigError(source, "scene", "at least one [[scene]] is required", scenes_mod.BUILTINS)
    scenes = []
    for i, t in enumerate(scene_tables):
        scenes += scenes_mod.parse_scene(t, source, f"scene[{i}]", base)

    lights = []
    for i, t in enumerate(_array_of_tables(raw, "light", source)):
        lights.append(_parse_light(t, source, f"light[{i}]"))
    if not lights:
        lights = [LightSpec("scene", label="scene")]

    m = _table(raw, "map", source)
    _check_keys(m, ("resolution", "texels", "filter", "format", "view"), source, "map")
    if "resolution" in m and "texels" in m:
        raise ConfigError(source, "map", "give either resolution (per face) or texels (total per view), not both",
                          ("resolution", "texels"))
    texels = tuple(_number(r, source, "map.texels", integer=True, minimum=1, maximum=6 * 16384 ** 2)
                   for r in _as_list(m.get("texels", [])))
    resolutions = tuple(_number(r, source, "map.resolution", integer=True, minimum=1, maximum=16384)
                        for r in _as_list(m.get("resolution", 512)))
    filters = tuple(_choice(f, source, "map.filter", FILTERS) for f in _as_list(m.get("filter", "nearest")))
    formats = tuple(_choice(f, source, "map.format", FORMATS) for f in _as_list(m.get("format", "float32")))
    views = tuple(_choice(v, source, "map.view", POINT_VIEWS) for v in _as_list(m.get("view", "dual_paraboloid")))
    for key, vals in (("map.resolution", resolutions), ("map.filter", filters), ("map.format", formats),
                      ("map.view", views)):
        if not vals:
            raise ConfigError(source, key, "empty list")
    if "view" in m and all(l.type not in ("point", "scene") for l in lights):
        # a scene's own lights are known only once it is loaded; explicit ones are known now
        raise ConfigError(source, "map.view", "views are for point lights and no [[light]] is a point light "
                          f"(the lights are {', '.join(sorted({l.type for l in lights}))}); remove map.view or "
                          "add a point light")
    mapspec = MapSpec(resolutions, filters, formats, views, texels)

    scheme_tables = _array_of_tables(raw, "scheme", source)
    if not scheme_tables:
        raise ConfigError(source, "scheme", "at least one [[scheme]] is required", [s.NAME for s in REGISTRY])
    schemes = []
    for i, t in enumerate(scheme_tables):
        schemes += _parse_scheme(t, source, f"scheme[{i}]", REGISTRY, PRESETS)

    mem = _table(raw, "memory", source)
    _check_keys(mem, ("budget_mb",), source, "memory")
    budget = (_number(mem["budget_mb"], source, "memory.budget_mb", positive=True)
              if "budget_mb" in mem else None)

    tim = _table(raw, "timing", source)
    _check_keys(tim, ("repeats",), source, "timing")
    repeats = _number(tim.get("repeats", 3), source, "timing.repeats", integer=True, minimum=1, maximum=100)


    return Config(name=name, source=source, seed=seed, variant=variant, camera_resolution=camera_resolution,
                  scenes=tuple(scenes), lights=tuple(lights), map=mapspec, schemes=tuple(schemes),
                  timing_repeats=repeats, memory_budget_mb=budget, raw=raw)


def _table(raw, key, source) -> dict:
    t = raw.get(key, {})
    if not isinstance(t, dict):
        raise ConfigError(source, key, f"expected a table [{key}]")
    return t


def _array_of_tables(raw, key, source) -> list:
    t = raw.get(key, [])
    if isinstance(t, dict):
        t = [t]
    if not isinstance(t, list) or not all(isinstance(x, dict) for x in t):
        raise ConfigError(source, key, f"expected an array of tables [[{key}]]")
    return t


def _parse_light(t: dict, source: str, where: str) -> LightSpec:
    kind = _choice(t.get("type"), source, f"{where}.type", LIGHT_TYPES) if "type" in t else None
    if kind is None:
        raise ConfigError(source, f"{where}.type", "missing", LIGHT_TYPES)
    allowed = {"scene": ("type",), "directional": ("type", "direction"),
               "spot": ("type", "position", "target", "direction", "cutoff"),
               "point": ("type", "position", "direction")}[kind]
    _check_keys(t, allowed, source, where)
    if kind == "scene":
        return LightSpec("scene", label="scene")
    if kind == "directional":
        if "direction" not in t:
            raise ConfigError(source, f"{where}.direction", "a directional light needs a direction")
        d = _vec3(t["direction"], source, f"{where}.direction", nonzero=True)
        return LightSpec("directional", direction=d, label="directional")
    if kind == "point":
        if "position" not in t:
            raise ConfigError(source, f"{where}.position", "a point light needs a position")
        pos = _vec3(t["position"], source, f"{where}.position")
        # main direction: the paraboloid's axis (its hemisphere), the dual paraboloid's front map
        d = _vec3(t.get("direction", [0.0, 0.0, -1.0]), source, f"{where}.direction", nonzero=True)
        return LightSpec("point", position=pos, direction=d, label="point")
    if "position" not in t:
        raise ConfigError(source, f"{where}.position", "a spot light needs a position")
    pos = _vec3(t["position"], source, f"{where}.position")
    if ("target" in t) == ("direction" in t):
        raise ConfigError(source, where, "a spot light needs exactly one of target or direction",
                          ("target", "direction"))
    target = _vec3(t["target"], source, f"{where}.target") if "target" in t else None
    direction = _vec3(t["direction"], source, f"{where}.direction", nonzero=True) if "direction" in t else None
    if target is not None and target == pos:
        raise ConfigError(source, f"{where}.target", "the target equals the position")
    cutoff = _number(t.get("cutoff", 30.0), source, f"{where}.cutoff", positive=True, maximum=85.0)
    return LightSpec("spot", position=pos, target=target, direction=direction, cutoff=cutoff, label="spot")


def _parse_scheme(t: dict, source: str, where: str, registry, presets) -> list:
    names = [s.NAME for s in registry]
    if "preset" in t:
        preset = _choice(t["preset"], source, f"{where}.preset", sorted(presets))
        extra = set(t) - {"preset"}
        if extra:
            raise ConfigError(source, f"{where}.{sorted(extra)[0]}", "a preset takes no other keys", ("preset",))
        name, values = presets[preset]
        module = next(s for s in registry if s.NAME == name)
        return [SchemeSpec(name, module.Params(**values), preset=preset)]
    if "name" not in t:
        raise ConfigError(source, f"{where}.name", "missing", names)
    name = _choice(t["name"], source, f"{where}.name", names)
    module = next(s for s in registry if s.NAME == name)
    return [SchemeSpec(name, p) for p in sweep_params(module.Params, t, source, where, skip=("name",))]
