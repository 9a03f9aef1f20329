"""No bias (Williams 1978): the plain two-pass shadow test.

Lit when the receiver's depth is at most the first layer's depth, ``d <= z1``. Acne is
expected wherever the depth of a texel's centre differs from the receiver's own: on a plane
tilted against the light about half of its receivers fall below their texel's sample.
Kept as the baseline every other scheme is measured against.
"""
from dataclasses import dataclass
from .base import fixed_needs, no_shift

NAME = "none"
SOURCE = "Williams 1978"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """No parameters."""
    pass


def margin(rx, tap, p):
    """z1 - d, in view depth units."""
    return tap.z1 - rx.depth


shift = no_shift
