"""A voxelized shadow volume's voxel test with a constant epsilon (Dou et al. 2014, section 3.3).

The receiver is moved toward the light by ``epsilon = K * sceneScale`` (``sceneScale`` the scene's
bounding-box diagonal; along the receiver's own light ray, so it stays in its theta and phi cell)
and the voxel of that point is looked up. One world length for the whole grid, while the grid's
alpha voxels are non-uniform in world space (epipolar sampling): too small leaves acne where the
voxels are deep, too large detaches shadows where they are shallow (Dou et al.'s figure 8, left).
Where the view ray and the light ray are parallel (the receiver seen from near the light's
direction) moving along the light ray leaves alpha unchanged and the epsilon does nothing.

Parameters: ``K`` (default 0.01), ``alpha`` (voxels per light ray), ``occupancy`` (centre | hit).
Only on the ``vsv`` view.
"""
from dataclasses import dataclass, field

import drjit as dr

from ..maps.vsv import voxel_lit
from .vsv import Params as GridParams
from .base import fixed_needs, no_shift

NAME = "vsv_epsilon"
SOURCE = "Dou et al. 2014 sec. 3.3 (constant epsilon)"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = ("vsv",)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params(GridParams):
    """The epsilon's fraction of the scene's diagonal, the grid's alpha resolution and occupancy rule."""
    K: float = field(default=0.01, metadata={"doc": "epsilon toward the light as a fraction of the scene's diagonal",
                                             "min": 0.0})


def margin(rx, tap, p):
    """The voxel of the receiver moved epsilon toward the light, tested in the tap's column (lit where >= 0)."""
    moved = rx.p_world + rx.to_light * (p.K * rx.scene_scale)
    return voxel_lit(dr.floor(rx.view.depth(moved) * p.alpha), tap.z1 * p.alpha, p.alpha, p.occupancy)


shift = no_shift
