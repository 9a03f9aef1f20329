"""dsm: measure shadow-map bias schemes against exact ray-traced visibility (Mitsuba 3, Dr.Jit)."""
from .config import load as load_config, parse as parse_config
from .types import ConfigError, Length

__version__ = "0.1.0"


def run(config, out=None, variant=None, progress=False):
    """Run an experiment (Config, dict or TOML path) and return its :class:`dsm.runner.Results`."""
    from .runner import run as _run
    return _run(config, out=out, variant=variant, progress=progress)


def register():
    """Register the Mitsuba integrator plugins dsm_shadow and dsm_error for the current variant."""
    from .env import register_plugins
    return register_plugins()


def _register_if_variant_set():
    # a variant can only be set once mitsuba is imported: importing it here would cost every
    # process that uses dsm without Mitsuba (the report's drawing workers) a second
    import sys
    mi = sys.modules.get("mitsuba")
    if mi is not None and mi.variant() is not None:
        register()


_register_if_variant_set()

__all__ = ["run", "register", "ConfigError", "Length", "load_config", "parse_config"]
