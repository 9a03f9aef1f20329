"""Bias schemes: one module each, listed explicitly, each meeting :class:`base.Scheme`.

Each module has ``NAME``, ``SOURCE``, ``NEEDS`` (the map attributes it reads), a frozen
``Params`` dataclass with defaults and units, a signed ``margin(rx, tap, params) -> Float``
over Dr.Jit arrays (lit where >= 0), ``shift(rx, params) -> Receiver`` (the identity,
:func:`base.no_shift`, but for schemes that move the lookup point), ``needs(params) ->
frozenset`` (an instance's own layers, a subset of ``NEEDS``: :func:`needs_of`), ``VIEWS`` and
``READS_CAMERA`` (:class:`base.Scheme`).

Engine presets (:mod:`.presets`) are :mod:`combined` instances per light type:
:func:`preset_for_light` resolves one for a light.

Lookups of other shadow representations (``VOXEL_REGISTRY``: a voxelized shadow volume's voxel
tests, :mod:`dsm.maps.vsv`) meet the same contract and name the views they read (``VIEWS``); a
shadow-map scheme, which names none, reads every view but those (:func:`reads_view`). ``ALL``
is every scheme a config may name; ``REGISTRY`` stays the shadow-map schemes.
"""

from . import adaptive, adaptive_tap, combined, constant, distance_normal, dual, midpoint, none, normal_angle, normal_offset, receiver_plane, second_depth, slope_scaled, vsv, vsv_adaptive, vsv_epsilon
from ..core.types import Length, describe_params

from .base import Scheme

REGISTRY = (none, constant, slope_scaled, normal_angle, normal_offset, combined, receiver_plane, adaptive, midpoint,
            dual, second_depth, adaptive_tap, distance_normal)
VOXEL_REGISTRY = (vsv, vsv_epsilon, vsv_adaptive)
ALL = REGISTRY + VOXEL_REGISTRY
EXCLUSIVE_VIEWS = frozenset(v for m in VOXEL_REGISTRY for v in m.VIEWS)   # views only their own lookups read
_broken = [m.NAME for m in ALL if not isinstance(m, Scheme)]
assert not _broken, f"scheme modules not meeting the Scheme contract: {_broken}"

# Engine presets: a named engine's default bias, measurable beside every scheme (per light type).
from .presets import PRESETS, preset_for_light
from ..core.suggest import unknown


def get(name: str):
    """The scheme module named ``name``; KeyError listing the valid names."""
    for s in ALL:
        if s.NAME == name:
            return s
    raise KeyError(unknown("scheme", name, [s.NAME for s in ALL]))


def reads_view(spec, view: str) -> bool:
    """Whether a scheme instance reads maps of view kind ``view``: its own ``VIEWS``, else every
    view but the exclusive ones (a voxel grid is no depth map)."""
    own = get(spec.name).VIEWS
    return view in own if own is not None else view not in EXCLUSIVE_VIEWS


def culling_of(params) -> str:
    """The map culling a scheme instance asks for (``none`` for schemes without the parameter)."""
    return getattr(params, "culling", "none")


def needs_of(scheme_specs) -> set:
    """The map attributes (beyond z1 and shape ids) a group of scheme instances reads."""
    out = set()
    for s in scheme_specs:
        out |= set(get(s.name).needs(s.params))
    return out


def view_mismatch(specs, views) -> str:
    """What a config's scheme instances and ``[map] view`` choices leave unmatched, in words
    ('' when nothing): a lookup whose views none names, or an exclusive view no lookup reads."""
    for s in specs:
        own = get(s.name).VIEWS
        if own is not None and not set(own) & set(views):
            return f"scheme {s.name} reads only a {' or '.join(own)} view: add it to map.view"
    for v in sorted(set(views) & EXCLUSIVE_VIEWS):
        if not any(reads_view(s, v) for s in specs):
            readers = ", ".join(m.NAME for m in VOXEL_REGISTRY if v in m.VIEWS)
            return f"view {v} is read by its own lookups only ({readers}) and no [[scheme]] is one"
    return ""
