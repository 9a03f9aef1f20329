"""Adaptive depth bias per filter tap, after Ehm et al. 2015 ("Adaptive Depth Bias for Soft
Shadows"), who extend Dou et al.'s adaptive bias (JCGT 2014) to filtered lookups.

What is implemented: for every tap of a filter (PCF, wide PCF, PCSS's blocker search and its
PCF) the light ray through that tap's texel centre is intersected with the receiver's tangent
plane (geometric normal); that depth, plus Dou's adaptive epsilon (eq. 10: ``K * sceneScale``
in the kit's linear depths), is the tap's receiver depth. A planar receiver thus compares each
tap against its own plane at that tap, not against the receiver's single depth, which a wide
kernel on a slope needs (a constant bias large enough for the farthest tap of a wide kernel
floods the near ones with peter-panning).

Where it departs from the paper: (1) the paper's text was not at hand, so only the per-tap
tangent-plane depth and Dou's epsilon are reproduced, not any further refinement of theirs;
(2) a clamp of our own: the plane depth is kept within ``max_slope`` times the tap's lateral
distance (its offset in texels times the receiver's texel width) of the receiver's depth, so a
tangent plane almost parallel to the light ray (Dou's figure 9) cannot be extrapolated across a
wide kernel into an unbounded bias; ``max_slope = inf`` turns the clamp off; (3) where a tap's
ray misses the plane (parallel, or behind the light) the receiver's own depth is used, as in
the kit's ``adaptive``. With the nearest filter it equals ``adaptive`` (the tap is the
receiver's own texel, at lateral distance below one texel).

Parameters: ``K`` (default 0.0001, Dou's value), ``max_slope`` (default 8: planes up to about
83 degrees from the light direction are followed exactly).
"""
from dataclasses import dataclass, field

import drjit as dr

from .base import fixed_needs, no_shift

NAME = "adaptive_tap"
SOURCE = "Ehm et al. 2015 after Dou et al. 2014"
NEEDS = frozenset()
USES_PLANE = True
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Per-tap adaptive bias's parameters: ``K`` (a fraction of the diagonal) and the plane's clamp ``max_slope``."""
    K: float = field(default=1e-4, metadata={"doc": "epsilon as a fraction of the scene's diagonal", "min": 0.0})
    max_slope: float = field(default=8.0, metadata={"doc": "largest plane depth change per world unit of a tap's "
                                                           "offset", "min": 0.0})


def margin(rx, tap, p):
    """z1 + K * diagonal less the tap's plane depth, held within ``max_slope`` times its lateral distance of ``d``."""
    plane = tap.receiver_plane_depth(rx)
    du, dv = tap.cu_map - rx.u_map, tap.cv_map - rx.v_map
    # a tap's lateral distance: at least one texel (the receiver's own texel holds its centre)
    reach = p.max_slope * dr.maximum(dr.sqrt(du * du + dv * dv), 1.0) * rx.texel_world
    plane = dr.clip(plane, rx.depth - reach, rx.depth + reach)
    return tap.z1 + p.K * rx.scene_scale - plane


shift = no_shift
