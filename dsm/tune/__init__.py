"""Tuning by gradient (dsm tune): relaxed objective, search, bias maps, resume."""
import importlib

# The names of the module this folder replaced (dsm/tune.py before the layout of docs/design.md, then
# tuner.py, split into these): an old import path kept as a thin alias for one release.
_OLD_HOMES = ('tuner', 'output', 'search', 'refine', 'compare', 'relax', 'evaluate', 'cases', 'bias_map')


def __getattr__(name: str):
    """A name of the old flat module, read from its new home (for one release)."""
    for home in _OLD_HOMES:
        module = importlib.import_module(f"{__name__}.{home}")
        if hasattr(module, name):
            return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
