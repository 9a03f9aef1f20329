"""Dual depth layers (Weiskopf & Ertl 2003).

Lit when ``d <= z1 + min((z2 - z1) / 2, z_offset)``: the midpoint where caster and receiver
are close, a constant offset where the second surface is far away (which removes midpoint's
self-unshadowing). With back-face culling of closed meshes (``back_closed``, as the paper
recommends, open surfaces unculled) the second surface behind a silhouette is no longer the
object's own back face, which removes midpoint's self-shadowing at silhouettes.

Parameters: ``z_offset`` (length, default ``"4 texel"``), ``culling`` (none | back | front |
back_closed, default back_closed).
"""
from dataclasses import dataclass, field

import drjit as dr

from ..core.types import Length
from ..core.types import CULLINGS as CULLING
from .base import fixed_needs, no_shift

NAME = "dual"
SOURCE = "Weiskopf & Ertl 2003"
NEEDS = frozenset({"z2"})
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Dual layers' parameters: ``z_offset``, the largest bias, and the map's ``culling`` per shape."""
    z_offset: Length = field(default=Length(4.0, "texel"), metadata={"min": 0.0, "doc": "largest bias"})
    culling: str = field(default="back_closed", metadata={"doc": "map culling per shape", "choices": CULLING})


def margin(rx, tap, p):
    """z1 + min((z2 - z1) / 2, z_offset) - d, in view depth units."""
    return tap.z1 + dr.minimum(0.5 * (tap.z2 - tap.z1), p.z_offset) - rx.depth


shift = no_shift
