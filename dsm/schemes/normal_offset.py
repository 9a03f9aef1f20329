"""Normal-offset shadows (three.js ``normalBias``, Bevy, Godot, Unity).

The lookup point moves along the receiver's geometric normal by ``offset`` before it is
projected into the map; then ``d' <= z1(p') + bias``. Because the offset is lateral as well
as in depth, it removes acne without pushing the shadow off its contact as far as an
equal depth bias, but it shifts and shrinks shadows by up to ``offset`` sideways.

Parameters: ``offset`` (length, default ``"1 texel"``), ``bias`` (length, default ``0``).
"""
from dataclasses import dataclass, field

from ..core.types import Length
from .base import fixed_needs

NAME = "normal_offset"
SOURCE = "three.js, Bevy, Godot, Unity (normal bias)"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Normal offset's parameters: ``offset`` along the normal and ``bias``, the depth offset added to z1."""
    offset: Length = field(default=Length(1.0, "texel"), metadata={"doc": "move along the normal"})
    bias: Length = field(default=Length(0.0, "world"), metadata={"doc": "depth offset added to z1"})


def shift(rx, p):
    """The receiver moved along its geometric normal by ``offset`` (world units)."""
    return rx.moved(rx.p_world + rx.n_world * p.offset)


def margin(rx, tap, p):
    """z1(p') + bias - d' at the moved receiver, in view depth units."""
    return tap.z1 + p.bias - rx.depth
