"""The maps' cache policies of a ``[[motion]]`` path ([[motion]] cache), one module each.

A policy says, per frame, whether a planned map is cast again given whether its view's
signature changed and whether a caster moved since the map kept was cast. The policies'
names are core.types.CACHE_POLICIES (the config's choices); this registry checks each module
against the Policy protocol at import."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..core.types import CACHE_POLICIES
from . import cache_none, cache_static


@runtime_checkable
class Policy(Protocol):
    """What the frame loop reads of a cache policy module."""
    NAME: str

    def rebuild(self, view_changed: bool, geometry_changed: bool) -> bool:
        """Whether the frame's map is cast again."""


REGISTRY = {m.NAME: m for m in (cache_none, cache_static)}
assert tuple(REGISTRY) == CACHE_POLICIES, "core.types.CACHE_POLICIES lists the registry's policies"
assert all(isinstance(m, Policy) for m in REGISTRY.values())


def get(name: str) -> Policy:
    """The policy module named ``name`` (one of CACHE_POLICIES)."""
    return REGISTRY[name]
