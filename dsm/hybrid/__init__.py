"""Hybrid lookups: the map answers where a rule says it is sure, a ray decides elsewhere.

Rules are modules meeting :class:`base.Rule` (``NAME``, ``SOURCE``, ``Params``, ``select``):
:mod:`classifier` (AMD FidelityFX Shadow Classifier), :mod:`band` (|d - z1| < k texels),
:mod:`oracle` (the map's wrong receivers: the floor) and :mod:`all` (every receiver). Where a
ray starts: :mod:`origins`. One instance on one case: :func:`trace.measure` (called by
dsm.case.evaluate).
"""
from . import all as all_rule, band, classifier, oracle
from .base import Inputs, Rule, Selection
from ..core.suggest import unknown

REGISTRY = (classifier, band, oracle, all_rule)
BY_NAME = {r.NAME: r for r in REGISTRY if isinstance(r, Rule)}
assert len(BY_NAME) == len(REGISTRY), "a hybrid rule module does not meet the Rule contract, or a name repeats"


def get(name: str):
    """The rule module named ``name``; KeyError listing the valid names."""
    if name not in BY_NAME:
        raise KeyError(unknown("hybrid rule", name, BY_NAME))
    return BY_NAME[name]


def names() -> tuple:
    """The rules a config may name."""
    return tuple(BY_NAME)
