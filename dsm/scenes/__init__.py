"""Scenes: parameters, built-ins, mesh and XML files, loading, checks, closedness, the G-buffer, the exact frame."""
import importlib
from pathlib import Path

# The names of the module this folder replaced (dsm/{name}.py before the layout of
# docs/design.md): an old import path kept as a thin alias for one release.
_OLD_HOMES = ('load', 'params', 'builtins', 'geometry', 'camera', 'files', 'ply', 'emitters', 'checks', 'spec',
              'data')


def __getattr__(name: str):
    """A name of the old flat module, read from its new home (for one release)."""
    if (Path(__file__).parent / f"{name}.py").is_file():
        # a submodule not imported yet (``from . import exact_frame`` asks here first): imported as
        # itself, not searched for in the homes, which may be half-imported at that moment
        return importlib.import_module(f"{__name__}.{name}")
    for home in _OLD_HOMES:
        module = importlib.import_module(f"{__name__}.{home}")
        if hasattr(module, name):
            return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
