"""Hybrid lookups: the map answers where a rule says it is sure, a ray decides elsewhere.

Rules are modules meeting :class:`base.Rule` (``NAME``, ``SOURCE``, ``Params``, ``select``):
:mod:`classifier` (AMD FidelityFX Shadow Classifier), :mod:`band` (|d - z1| < k texels),
:mod:`oracle` (the map's wrong receivers: the floor) and :mod:`all` (every receiver). Where a
ray starts: :mod:`origins`. One instance on one case: :func:`trace.measure` (called by
dsm.case.evaluate).
"""
from . import all as all_rule, band, classifier, oracle
from .base import Inputs, Rule, Selection

REGISTRY = (classifier, band, oracle, all_rule)
_broken = [m.NAME for m in REGISTRY if not isinstance(m, Rule)]
assert not _broken, f"hybrid rule modules not meeting the Rule contract: {_broken}"


def get(name: str):
    """The rule module named ``name``; KeyError listing the valid names."""
    for r in REGISTRY:
        if r.NAME == name:
            return r
    raise KeyError(f"unknown hybrid rule {name!r} (valid: {', '.join(r.NAME for r in REGISTRY)})")


def names() -> tuple:
    """The rules a config may name."""
    return tuple(r.NAME for r in REGISTRY)
