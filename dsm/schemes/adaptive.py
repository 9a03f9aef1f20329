"""Adaptive depth bias (Dou, Yan, Kerzner, Dai & Wyman, JCGT 2014).

The receiver's potential occluder is where the light ray through the texel centre meets the
receiver's tangent plane; the receiver is moved to that depth and then "just above" it by
the adaptive epsilon of their eq. 10. Depths here are linear world depths, where eq. 10's
``f'(x) dx`` is ``dx = K * sceneScale`` itself (``sceneScale`` = the scene's bounding-box
diagonal); a stored non-linear format applies the compression derivative.

Parameters: ``K`` (default 0.0001, as in all of the paper's experiments).
Known failure: receivers whose tangent plane is almost parallel to the light ray are
over-biased (the paper's figure 9), which shading hides but the metrics count.
"""
from dataclasses import dataclass, field
from .base import fixed_needs, no_shift
# the receiver plane's test with another offset, so it declares what that scheme declares (USES_PLANE)
from .receiver_plane import USES_PLANE, plane_margin

NAME = "adaptive"
SOURCE = "Dou et al. 2014"
NEEDS = frozenset()
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Adaptive bias's parameter: ``K``, the epsilon as a fraction of the scene's diagonal."""
    K: float = field(default=1e-4, metadata={"doc": "epsilon as a fraction of the scene's diagonal", "min": 0.0})


def margin(rx, tap, p):
    """Receiver plane's test with the offset K * diagonal (Dou et al.'s epsilon)."""
    return plane_margin(rx, tap, p.K * rx.scene_scale)


shift = no_shift
