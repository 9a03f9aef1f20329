"""dsm: measure shadow-map bias schemes against exact ray-traced visibility (Mitsuba 3, Dr.Jit)."""
from .config import ConfigError, Length, load as load_config, parse as parse_config

__version__ = "0.1.0"


def run(config, out=None, variant=None, progress=False):
    """Run an experiment (Config, dict or TOML path) and return its :class:`dsm.runner.Results`."""
    from .runner import run as _run
    return _run(config, out=out, variant=variant, progress=progress)


__all__ = ["run", "ConfigError", "Length", "load_config", "parse_config"]
