"""The report: the run's files (io), tables, figures, report.html; publish is the only composer."""
import importlib

# The names of the module this folder replaced (dsm/{name}.py before the layout of
# docs/design.md): an old import path kept as a thin alias for one release.
_OLD_HOMES = ('tables', 'io')


def __getattr__(name: str):
    """A name of the old flat module, read from its new home (for one release)."""
    for home in _OLD_HOMES:
        module = importlib.import_module(f"{__name__}.{home}")
        if hasattr(module, name):
            return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
