"""[[scene]] tables into scene specs: a built-in or a file, list-valued parameters swept, checked up front."""
from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from ..core.types import ConfigError, SceneSpec, sweep_params
from .builtins import builtin_geometry, scale_range
from .checks import check_held
from .files import mesh_arrays
from .models import MODEL_KEYS, MODELS, absent_message, locate, version_of
from .params import BUILTINS, FILE_SUFFIXES, FileParams, GrazingParams, PlaneParams


XML_KEYS = ("scale", "translate", "precision")   # what an XML scene takes of FileParams: its units, place and how the engine holds them (dsm.scenes.xml_scale)

def parse_scene(t: dict, source: str, where: str, base: Path) -> list[SceneSpec]:
    """One [[scene]] table, with list-valued parameters swept, into scene specs."""
    if "model" in t:
        return _model_scene(t, source, where, base)
    if "version" in t:
        raise ConfigError(source, f"{where}.version", "a version is a named model's (give model too)", list(MODELS))
    if ("builtin" in t) == ("file" in t):
        raise ConfigError(source, where, "a scene needs exactly one of builtin or file", ("builtin", "file"))
    if "builtin" in t:
        name = t["builtin"]
        if not isinstance(name, str) or name not in BUILTINS:
            raise ConfigError(source, f"{where}.builtin", f"unknown scene {name!r}", list(BUILTINS), got=name)
        raw = sweep_params(BUILTINS[name], t, source, where, skip=("builtin", "closed"))
        labels = [_label(name, p) for p in raw]          # a file as the config names it
        specs = [_with_paths(p, source, where, base) for p in raw]
        for p in specs:
            _check_builtin(name, p, source, where)
        closed = _closed_override(t, source, where)
        shape_names = list(builtin_geometry(name, specs[0])[0])
        for shape, _ in closed:
            if shape not in shape_names:
                raise ConfigError(source, f"{where}.closed.{shape}", f"no shape named {shape!r} in {name}", shape_names)
        return [SceneSpec(builtin=name, params=p, label=label, closed=closed, source=source, where=where)
                for p, label in zip(specs, labels)]
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
    unknown = sorted(k for k in t if k not in {f.name for f in fields(FileParams)} | {"file", "closed", "optional"})
    if path.suffix.lower() == ".xml" and unknown:
        # an XML scene's valid keys, not a mesh file's (those it takes, it refuses below by name)
        raise ConfigError(source, f"{where}.{unknown[0]}", "unknown key", ("file", "closed", "optional") + XML_KEYS,
                          got=unknown[0])
    specs = sweep_params(FileParams, t, source, where, skip=("file", "closed", "optional"))
    if not path.is_file():
        return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()),
                          missing=f"skipped: {path} is absent (optional scene)", source=source, where=where)
                for p in specs]
    closed = _closed_override(t, source, where)
    given = [f.name for f in fields(FileParams) if f.name not in XML_KEYS and any(
        getattr(p, f.name) != getattr(FileParams(), f.name) for p in specs)]
    if path.suffix.lower() == ".xml" and given:
        raise ConfigError(source, f"{where}.{given[0]}", "an XML scene takes no "
                          f"{'/'.join(f.name for f in fields(FileParams) if f.name not in XML_KEYS)} keys: its "
                          "geometry, camera and lights are the file's, in its own world coordinates (scale: in other "
                          "units; translate: elsewhere)", ("file", "closed", "optional") + XML_KEYS)
    return [SceneSpec(file=path, params=p, label=_label(path.stem, p, FileParams()), closed=closed, source=source,
                      where=where) for p in specs]


def resolve_path(raw: str, suffixes: tuple, source: str, key: str, base) -> Path:
    """File name ``raw`` resolved against the config's folder ``base``; a ConfigError at ``key`` for a type
    not among ``suffixes`` or a file that is not there."""
    path = Path(raw).expanduser()
    path = path if path.is_absolute() else (Path(base or ".") / path).resolve()
    if path.suffix.lower() not in suffixes:
        raise ConfigError(source, key, f"unsupported file type {path.suffix!r}", suffixes)
    if not path.is_file():
        raise ConfigError(source, key, f"no such file: {path}")
    return path


def _with_paths(p, source: str, where: str, base: Path):
    """A built-in's parameters with each file it names (a field whose metadata has ``path``: its suffixes)
    resolved against the config's folder and checked as the kit's mesh loading reads it (dsm.scenes.files)."""
    given = {}
    for f in fields(p):
        suffixes, raw = f.metadata.get("path"), getattr(p, f.name)
        if suffixes is None or not raw:
            continue
        key = f"{where}.{f.name}"
        path = resolve_path(raw, suffixes, source, key, base)
        mesh_arrays(path, source, key)
        given[f.name] = str(path)
    return replace(p, **given)


def _model_scene(t: dict, source: str, where: str, base: Path) -> list[SceneSpec]:
    """A [[scene]] with ``model`` (a model the kit does not ship): the user's copy from ``file`` or
    the model's environment variable, placed in the model's frame; skipped, saying how to get
    one, where there is none."""
    name = t["model"]
    if not isinstance(name, str) or name not in MODELS:
        raise ConfigError(source, f"{where}.model", f"unknown model {name!r}", list(MODELS), got=name)
    if "builtin" in t or "optional" in t:
        key = "builtin" if "builtin" in t else "optional"
        raise ConfigError(source, f"{where}.{key}", f"a model's scene takes no {key} key (an absent copy is "
                          "skipped, saying how to get one)", ("model", "version", "file"))
    model = MODELS[name]
    names = [v.name for v in model.versions]
    if "version" in t and t["version"] not in names:          # a config mistake, with or without a copy
        raise ConfigError(source, f"{where}.version", f"unknown {model.name} version {t['version']!r}", names,
                          got=t['version'])
    raw = t.get("file")
    if raw is not None and not isinstance(raw, str):
        raise ConfigError(source, f"{where}.file", f"expected a path string, got {raw!r}")
    path = locate(model, raw, base)
    if path is not None and path.is_dir():
        key = f"{where}.file" if raw is not None else model.env
        raise ConfigError(source, key, f"{path} is a folder, not {model.name}'s OBJ or PLY file", (".obj", ".ply"))
    rest = {k: v for k, v in t.items() if k not in MODEL_KEYS and k != "file"}
    if path is None or not path.is_file():
        specs = sweep_params(FileParams, rest, source, where, skip=("closed",))
        return [SceneSpec(file=path, params=p, label=_label(name, p, FileParams()), model=name,
                          missing=absent_message(model, path, source, where), source=source, where=where) for p in specs]
    if path.suffix.lower() not in (".obj", ".ply"):
        raise ConfigError(source, f"{where}.file", f"{model.name}'s copy must be a mesh file, not "
                          f"{path.suffix!r}", (".obj", ".ply"))
    version = version_of(model, path, t.get("version"), source, where)
    specs = parse_scene({**rest, "file": str(path)}, source, where, base)
    return [replace(s, model=name, units=version.units, label=_label(f"{name}_{version.name}", s.params,
                    FileParams())) for s in specs]


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
        check_held(float(np.ptp(v, axis=0).max()) * p.scale, p.translate, source, f"{where}.translate",
                    "from the origin")
    lo, hi = scale_range(name, p, shapes)
    if not lo <= p.scale <= hi:
        raise ConfigError(source, f"{where}.scale", f"{p.scale:g} is outside {lo:.2g} to {hi:.2g}, the scales at which "
                          "Mitsuba's float32 triangle normals of this scene neither overflow nor underflow")


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
