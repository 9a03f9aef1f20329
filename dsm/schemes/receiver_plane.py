"""Receiver plane depth bias (Isidoro 2006; Salcedo's shadow-map article).

Compares, at the texel's centre, the depth of the receiver's own plane there instead of the
receiver's depth: the light ray through the texel centre is intersected with the receiver's
tangent plane (geometric normal), so a planar receiver compares a surface with itself and
only rounding remains. ``bias`` absorbs that rounding. Known failure: curved or creased
receivers, where the tangent plane leaves the surface within one texel.

Parameters: ``bias`` (length, default ``"0.01 texel"``).
"""
from dataclasses import dataclass, field

from ..core.types import Length
from .base import fixed_needs, no_shift

NAME = "receiver_plane"
SOURCE = "Isidoro 2006; Salcedo's shadow-map article"
NEEDS = frozenset()
USES_PLANE = True     # compares the receiver plane's depth at the texel centre (lookup.plane_fallbacks)
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Receiver plane bias's parameter: ``bias``, the depth offset added to z1."""
    bias: Length = field(default=Length(0.01, "texel"), metadata={"doc": "depth offset added to z1"})


def plane_margin(rx, tap, offset):
    """z1 + ``offset`` less the receiver plane's depth at the tap's texel centre (view depth units):
    the test receiver_plane and adaptive share, with their own offsets."""
    return tap.z1 + offset - tap.receiver_plane_depth(rx)


def margin(rx, tap, p):
    """z1 + bias less the receiver plane's depth at the tap's texel centre."""
    return plane_margin(rx, tap, p.bias)


shift = no_shift
