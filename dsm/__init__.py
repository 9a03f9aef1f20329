"""dsm: measure shadow-map bias schemes against exact ray-traced visibility (Mitsuba 3, Dr.Jit)."""
import os

from .config.read import load as load_config, parse as parse_config
from .core.types import ConfigError, Length

__version__ = "0.5.0"


def run(config, out=None, variant=None, progress=False, *, force=False, resume=False, report=True):
    """Run an experiment (Config, dict, TOML path, or a Mitsuba scene .xml whose experiment is derived from it)
    and return its :class:`dsm.experiment.results.Results`; ``report=False`` skips the figures and report.html
    (as ``dsm run --no-report``: ``dsm report`` draws them later from the folder)."""
    from .experiment.runner import run as _run
    derived = None
    if isinstance(config, (str, os.PathLike)) and os.fspath(config).lower().endswith(".xml"):
        from .config import derive, derived_files, scene_facts
        derived = derive.derive(scene_facts.measure(os.fspath(config)))     # as dsm run SCENE.xml derives it
        config = derived_files.config_of(derived, out)
    if out is None:                      # a fresh temporary folder: no one else writes there
        return _run(config, out=None, variant=variant, progress=progress, report=report)
    return _run_in(config, out, variant, progress, force, resume, derived, report)


def _run_in(config, out, variant, progress, force, resume, derived=None, report=True):
    if force and resume:                 # as the command line refuses --force with --resume
        raise ConfigError("dsm.experiment", "force", "force=True replaces a run and resume=True goes on with it: give one")
    # dsm run's rules for --out (dsm.cli): the folder locked, a previous run kept unless
    # force replaces it or resume goes on with it, the config checked before the folder is touched
    from pathlib import Path
    from . import cli, pipeline
    from .experiment.lock import api_words, claim
    from .experiment.runner import Runner
    out = Path(out)
    config = pipeline.prepare(config, variant)
    held, problem = claim(out)
    if problem:
        raise ConfigError("dsm.experiment", "out", api_words(problem))
    with held:
        problem, resuming = cli.folder_problem(out, config, force, resume)
        if problem:
            raise ConfigError("dsm.experiment", "out", api_words(problem))
        if derived is not None:          # derived.toml and derivation.json beside the results, as dsm run writes them
            from .config import derived_files
            derived_files.write(derived, out)
        return Runner(config, out, variant, progress, resume_previous=resuming, report=report).run()


def register():
    """Register the Mitsuba integrator plugins dsm_shadow and dsm_error for the current variant."""
    from .core.env import register_plugins
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
