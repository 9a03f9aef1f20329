"""The maps' cache policies of a ``[[motion]]`` path ([[motion]] cache), one module each.

A policy says, per frame, whether a planned map is cast again given whether its view's
signature changed, whether a caster moved since the map kept was cast, the frames since then and
the policy's period (``stagger:N``'s N; 0 for the others). The policies' names are
core.types.CACHE_POLICIES (the config's choices; ``stagger:N`` is ``stagger`` with N); this
registry checks each module against the Policy protocol at import."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..core.types import CACHE_POLICIES
from functools import partial

from . import cache_invalidate, cache_none, cache_stagger, cache_static


@runtime_checkable
class Policy(Protocol):
    """What the frame loop reads of a cache policy module."""
    NAME: str
    PARTIAL: bool        # a caster's move re-casts the texels its bounds touch (dsm.experiment.texel_recast)

    def rebuild(self, view_changed: bool, geometry_changed: bool, age: int, period: int) -> bool:
        """Whether the frame's map is cast again."""


REGISTRY = {m.NAME: m for m in (cache_none, cache_static, cache_stagger, cache_invalidate)}
if tuple(REGISTRY) != tuple(p.partition(":")[0] for p in CACHE_POLICIES):
    raise TypeError(f"core.types.CACHE_POLICIES {CACHE_POLICIES} must list the registry's policies {tuple(REGISTRY)}")
for _module in REGISTRY.values():
    if not isinstance(_module, Policy):
        raise TypeError(f"{_module.__name__} lacks a field of the cache Policy protocol (NAME, PARTIAL, rebuild)")


def partial_recast(name: str) -> bool:
    """Whether the policy named by the config's ``cache`` value re-casts the texels a moving caster touches."""
    return REGISTRY[name.partition(":")[0]].PARTIAL


def rule(name: str):
    """(view_changed, geometry_changed, age) -> cast again, of the config's ``cache`` value (one of
    CACHE_POLICIES, ``stagger:N`` with its N)."""
    policy, _, period = name.partition(":")
    return partial(REGISTRY[policy].rebuild, period=int(period or 0))
