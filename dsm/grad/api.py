"""``dsm.grad.run(config)``: what ``dsm grad`` measures, as values, for Python users.

The same measuring as the command (the self-check; with ``compare`` the references and each
technique against them; with ``inverse`` the inverse task), returned rather than written: no
folder, no report. A notebook needs this module alone, and ``result.problem`` for its own losses
(one technique's loss and gradients: :func:`dsm.grad.evaluate`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..core import env
from ..core.types import ConfigError
from . import compare as comparemod
from . import inverse as inversemod
from . import spec as specmod
from .check import self_check
from .problem import Problem


@dataclass
class GradRun:
    """A config's gradients: its spec and problem, the self-check rows (check.CheckRow), and where asked
    the references per parameter (reference.Reference), the rows against them (compare.CompareRow) and
    the inverse task's runs (inverse.InverseRun)."""
    spec: specmod.GradSpec
    problem: Problem
    selfcheck: list
    references: dict | None = None
    compare: list | None = None
    inverse: list | None = None


def spec_of(config) -> specmod.GradSpec:
    """The GradSpec of ``config``: a GradSpec, a TOML path, or a config dict (``[gradient]`` and the kit's
    ``[[scene]]``, ``[[light]]``, ``[map]``, ``[[scheme]]``)."""
    if isinstance(config, specmod.GradSpec):
        return config
    if isinstance(config, (str, Path)):
        return specmod.load(config)
    if isinstance(config, dict):
        return specmod.parse(config, "<dict>")
    raise ConfigError("dsm.grad.run", "config", f"a GradSpec, a TOML path or a dict, got {type(config).__name__}")


def run(config, compare: bool = False, inverse: bool = False, variant: str | None = None) -> GradRun:
    """Measure ``config``'s gradients as ``dsm grad`` does (``--compare``, ``--inverse``) and return them."""
    spec = spec_of(config)
    if compare and spec.loss not in comparemod.LOSSES:
        raise ConfigError(spec.source, "gradient.loss", f"compare takes {spec.loss!r} loss only from a reference of "
                          f"its own (valid: {', '.join(comparemod.LOSSES)})")
    env.use_variant(variant)
    problem = Problem(spec)
    out = GradRun(spec, problem, self_check(problem))
    if compare:
        out.references = comparemod.references(problem)
        out.compare = comparemod.compare(problem, out.references)
    if inverse:
        out.inverse = inversemod.run_inverse(problem)
    return out
