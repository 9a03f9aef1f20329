"""Bias schemes: one module each, listed explicitly, each meeting :class:`base.Scheme`.

Each module has ``NAME``, ``SOURCE``, ``NEEDS`` (the map attributes it reads), a frozen
``Params`` dataclass with defaults and units, a signed ``margin(rx, tap, params) -> Float``
over Dr.Jit arrays (lit where >= 0) and ``shift(rx, params) -> Receiver`` (the identity,
:func:`base.no_shift`, but for schemes that move the lookup point). A module may add
``needs(params) -> frozenset``: an instance's own layers, a subset of ``NEEDS`` (:func:`needs_of`).

Engine presets (:mod:`.presets`) are :mod:`combined` instances per light type:
:func:`preset_for_light` resolves one for a light.
"""

from . import (adaptive, adaptive_tap, combined, constant, distance_normal, dual, midpoint, none, normal_angle,
               normal_offset, receiver_plane, second_depth, slope_scaled)
from ..types import Length, describe_params  # noqa: F401  (describe_params: the report's words)

from .base import Scheme

REGISTRY = (none, constant, slope_scaled, normal_angle, normal_offset, combined, receiver_plane, adaptive, midpoint,
            dual, second_depth, adaptive_tap, distance_normal)
_broken = [m.NAME for m in REGISTRY if not isinstance(m, Scheme)]
assert not _broken, f"scheme modules not meeting the Scheme contract: {_broken}"

# Engine presets: a named engine's default bias, measurable beside every scheme (per light type).
from .presets import PRESETS, preset_for_light  # noqa: E402,F401


def get(name: str):
    """The scheme module named ``name``; KeyError listing the valid names."""
    for s in REGISTRY:
        if s.NAME == name:
            return s
    raise KeyError(f"unknown scheme {name!r} (valid: {', '.join(s.NAME for s in REGISTRY)})")


def culling_of(params) -> str:
    """The map culling a scheme instance asks for (``none`` for schemes without the parameter)."""
    return getattr(params, "culling", "none")


def needs_of(scheme_specs) -> set:
    """The map attributes (beyond z1 and shape ids) a group of scheme instances reads."""
    out = set()
    for s in scheme_specs:
        module = get(s.name)
        own = getattr(module, "needs", None)
        out |= set(own(s.params) if own is not None else module.NEEDS)
    return out
