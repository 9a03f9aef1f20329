"""Midpoint shadow maps (Woo 1992; Weiskopf & Ertl 2003).

Lit when ``d <= (z1 + z2) / 2``: the comparison surface lies halfway between the first and
second surfaces along the texel's ray, so a lit surface passes by half the thickness of
whatever lies behind it. Failure modes (Weiskopf & Ertl 2003, figures 2 and 4): self-shadowing near
silhouettes, where front and back faces are close; with back-face culling, self-unshadowing
where a far background or the far plane drags the midpoint beyond the receiver.

Parameters: ``culling`` (none | back | front | back_closed, default none).
"""
from dataclasses import dataclass, field

from ..core.types import CULLINGS as CULLING
from .base import fixed_needs, no_shift

NAME = "midpoint"
SOURCE = "Woo 1992; Weiskopf & Ertl 2003"
NEEDS = frozenset({"z2"})
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Midpoint's parameter: the map's ``culling`` per shape."""
    culling: str = field(default="none", metadata={"doc": "map culling per shape", "choices": CULLING})


def margin(rx, tap, p):
    """(z1 + z2) / 2 - d, in view depth units."""
    return 0.5 * (tap.z1 + tap.z2) - rx.depth


shift = no_shift
