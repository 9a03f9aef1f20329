"""Slope-scaled depth bias (King 2004; the D3D/Vulkan/OpenGL rasterizer depth bias).

Lit when ``d <= z1 + min(clamp, bias + slope * m)``, where ``m`` is the caster's largest
depth change per texel step, computed from the caster's plane at the texel (as hardware does
from the triangle's depth gradient), not from neighbouring texels.

Defaults are the API values of Salcedo's shadow-map article (``setDepthBias(1, slopeScale: 3, clamp: 1/128)``):
``bias`` one unit of a 24-bit depth buffer over the view's depth range (``2^-24 range``),
``slope`` 3, ``clamp`` 1/128 of the depth range. Known failure: near-grazing casters reach
the clamp, which then acts as a large constant bias.
"""
from dataclasses import dataclass, field

import drjit as dr

from ..core.types import Length
from .base import fixed_needs, no_shift

NAME = "slope_scaled"
SOURCE = "King 2004; D3D/Vulkan/GL depth bias; Salcedo's shadow-map article"
NEEDS = frozenset({"slope"})
USES_PLANE = False
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Slope-scaled bias's parameters: the constant ``bias``, the factor ``slope`` on m and the ``clamp``."""
    bias: Length = field(default=Length(2.0 ** -24, "range"), metadata={"doc": "constant part"})
    slope: float = field(default=3.0, metadata={"doc": "factor on m, the caster's depth change per texel", "min": 0.0})
    clamp: Length = field(default=Length(1.0 / 128.0, "range"), metadata={"min": 0.0, "doc": "largest total bias"})


def margin(rx, tap, p):
    """z1 + min(clamp, bias + slope * m) - d, m the caster's depth change per texel (view depth units)."""
    return tap.z1 + dr.minimum(p.clamp, p.bias + p.slope * tap.slope) - rx.depth


shift = no_shift
