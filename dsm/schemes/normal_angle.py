"""Normal-angle bias (Gautron 2013; Salcedo's shadow-map article).

Lit when ``d <= z1 + min(max, bias * tan(theta))``, ``theta`` the angle between the
receiver's geometric normal and the direction to the light. ``tan(theta)`` is the receiver's
own depth slope per unit of lateral distance, so ``bias`` in texels is the half-width of the
depth error a texel can cause. Grazing receivers hit ``max``.

Parameters: ``bias`` (length, default ``"1 texel"``), ``max`` (length, default ``"8 texel"``).
"""
from dataclasses import dataclass, field

import drjit as dr

from ..core.types import Length
from .base import fixed_needs, no_shift

NAME = "normal_angle"
SOURCE = "Gautron 2013; Salcedo's shadow-map article"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Normal-angle bias's parameters: ``bias``, the scale of tan(theta), and ``max``, the largest bias."""
    bias: Length = field(default=Length(1.0, "texel"), metadata={"doc": "scale of tan(theta)"})
    max: Length = field(default=Length(8.0, "texel"), metadata={"min": 0.0, "doc": "largest bias"})


def margin(rx, tap, p):
    """z1 + min(max, bias * tan(theta)) - d, theta between the normal and the light (view depth units)."""
    cos_t = dr.clip(dr.dot(rx.n_world, rx.to_light), 0.0, 1.0)
    tan_t = dr.safe_sqrt(1.0 - cos_t * cos_t) / cos_t   # receivers have cos_t > 0
    return tap.z1 + dr.minimum(p.max, p.bias * tan_t) - rx.depth


shift = no_shift
