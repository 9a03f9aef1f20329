"""Named models the kit does not ship (Sponza): a user's copy found by a key or an environment
variable, which published version it is (told by its size, or a key), and the units that put it
in the model's frame, where the experiments' camera and light positions are written."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.types import ConfigError
from .ply import ply_positions


@dataclass(frozen=True)
class Version:
    """One published version of a model: its file units in the model's frame, and its size."""
    name: str
    units: float            # one file unit in the model's frame (the frame the configs' poses use)
    longest: tuple          # (lo, hi): the file's longest bounding-box side, in file units
    what: str               # in words, for messages and the README


@dataclass(frozen=True)
class Model:
    """A model a user supplies: its key, its environment variable, its versions, where to get one."""
    name: str
    env: str
    versions: tuple
    obtain: str


# The Dabrovic atrium (y up, about 34.8 x 16.5 x 15.6, courtyard floor at y = 0, centred on the
# origin in x and z) is the frame. Crytek's remodel is the same building in centimetres, y up,
# long along x and centred likewise (its commonly quoted bounds: x -1920.95 to 1799.91, y -126.44 to
# 1429.43, z -1182.81 to 1105.43), so 0.01 puts it in that frame.
SPONZA = Model(
    name="sponza", env="DSM_SPONZA",
    versions=(Version("dabrovic", 1.0, (25.0, 50.0), "Marko Dabrovic's atrium, about 35 units long"),
              Version("crytek", 0.01, (2500.0, 5000.0), "Frank Meinl's remodel for Crytek, in centimetres, "
                                                        "about 3,700 long")),
    obtain="Morgan McGuire's Computer Graphics Archive, https://casual-effects.com/data/ (both versions; "
           "their terms: data/meshes/README.md)")

MODELS = {"sponza": SPONZA}
MODEL_KEYS = ("model", "version")       # the [[scene]] keys a named model adds to a mesh file's


def locate(model: Model, raw_file, base: Path) -> Path | None:
    """The user's copy: ``file`` (relative to the config's folder) if given, else $env (relative to
    the working folder); None where neither is given."""
    raw = raw_file if raw_file is not None else os.environ.get(model.env) or None
    if raw is None:
        return None
    path = Path(raw).expanduser()
    if raw_file is not None and not path.is_absolute() and base is not None:
        path = base / path
    return path.resolve()


def absent_message(model: Model, path: Path | None, source: str, where: str) -> str:
    """Why a model's scene is skipped, in one line: the key, the variable, where to obtain a copy."""
    why = f"{path} is absent" if path is not None else f"neither its file key nor ${model.env} is set"
    return (f"skipped: {source}: {where}.model = \"{model.name}\" has no copy ({why}): give [[scene]] file = "
            f"\"<your copy>\" or set {model.env}=<your copy> (an OBJ or PLY of the "
            f"{' or '.join(v.name for v in model.versions)} version); obtain one from {model.obtain}")


def file_bounds(path: Path) -> tuple:
    """(lo, hi): the bounding box of an OBJ or PLY file's vertices, float64, in its own units."""
    if path.suffix.lower() == ".ply":
        v = ply_positions(path)
    else:
        rows = [(n, line.split()[1:4]) for n, line in enumerate(path.read_bytes().splitlines(), 1)
                if line.startswith(b"v ")]
        short = next((n for n, xyz in rows if len(xyz) < 3), None)
        if short is not None:           # a file cut short mid-line: say where, not numpy's "inhomogeneous shape"
            raise ValueError(f"line {short} is a vertex with fewer than 3 coordinates (a file cut short?)")
        v = np.array([xyz for _, xyz in rows], np.float64).reshape(-1, 3)
    if v.size == 0:
        raise ValueError(f"{path}: no vertices")
    return v.min(axis=0), v.max(axis=0)


def version_of(model: Model, path: Path, given, source: str, where: str) -> Version:
    """The version of ``model`` the file at ``path`` is: ``given`` (the [[scene]] version key), else
    the one whose size its longest side fits; a ConfigError naming the key where none fits."""
    names = [v.name for v in model.versions]
    if given is not None:
        if given not in names:
            raise ConfigError(source, f"{where}.version", f"unknown {model.name} version {given!r}", names, got=given)
        return model.versions[names.index(given)]
    try:
        lo, hi = file_bounds(path)
    except (OSError, ValueError) as e:
        raise ConfigError(source, f"{where}.file", f"cannot read the vertices of {path} to tell which "
                          f"{model.name} it is ({e}); give [[scene]] version", names) from None
    longest = float(np.max(hi - lo))
    for v in model.versions:
        if v.longest[0] <= longest <= v.longest[1]:
            return v
    sizes = "; ".join(f"{v.name}: {v.longest[0]:g} to {v.longest[1]:g}" for v in model.versions)
    raise ConfigError(source, f"{where}.version", f"{path}'s longest side is {longest:g}, the size of no "
                      f"{model.name} version ({sizes}): give the version key to say which it is", names)
