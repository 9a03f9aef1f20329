"""Second-depth shadow maps (Wang & Molnar 1994).

The map stores the first surface facing away from the light (front faces culled), so a lit
front face is compared with its own object's far side and needs no bias. Lit when
``d <= z_back + bias``. Wang & Molnar assume closed objects: with ``front_closed`` (the
default) front faces are culled on closed meshes only and open surfaces stay in the map as
they are, since culling an open one-sided plate would delete it.
Failure modes: thin closed objects (little depth between front and back) and open surfaces.

Parameters: ``bias`` (length, default 0), ``culling`` (front | front_closed, default front_closed).
"""
from dataclasses import dataclass, field

from ..core.types import Length
from .base import fixed_needs, no_shift

NAME = "second_depth"
SOURCE = "Wang & Molnar 1994"
NEEDS = frozenset()
USES_PLANE = False
CULLING = ("front", "front_closed")
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Second depth's parameters: ``bias`` on the stored depth and the map's ``culling`` per shape."""
    bias: Length = field(default=Length(0.0, "world"), metadata={"doc": "depth offset added to the stored depth"})
    culling: str = field(default="front_closed", metadata={"doc": "map culling per shape", "choices": CULLING})


def margin(rx, tap, p):
    """z_back + bias - d, z_back the first layer of the front-culled map (view depth units)."""
    return tap.z1 + p.bias - rx.depth


shift = no_shift
