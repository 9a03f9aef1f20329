"""Constant depth bias (Williams 1978).

Lit when ``d <= z1 + bias``. One number for the whole map: too small leaves acne on surfaces
steep to the light, too large detaches shadows from their casters (peter-panning) once it
exceeds the gap between caster and receiver.

Parameters: ``bias`` (length, default ``"1 texel"``).
"""
from dataclasses import dataclass, field

from ..core.types import Length
from .base import fixed_needs, no_shift

NAME = "constant"
SOURCE = "Williams 1978"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Constant bias's parameter: ``bias``, the depth offset added to z1."""
    bias: Length = field(default=Length(1.0, "texel"), metadata={"doc": "depth offset added to z1"})


def margin(rx, tap, p):
    """z1 + bias - d, in view depth units (lit where >= 0)."""
    return tap.z1 + p.bias - rx.depth


shift = no_shift
