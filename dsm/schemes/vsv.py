"""The plain voxel test of a voxelized shadow volume (Wyman 2011; Dou et al. 2014, section 3.3).

The receiver's own voxel (its theta and phi cell, its alpha voxel) is looked up in the binary
grid: lit when it is not occluded. Acne comes from the voxel that holds the surface itself: on a
lit plane, half of the receivers read a voxel whose centre lies behind the surface (``occupancy
= "centre"``), whatever the slope; more when the hit's own voxel is occluded (``"hit"``: 1 -
g / 8 for g = alpha voxels crossed per phi cell along the surface, g <= 2; docs/design.md).

Parameters: ``alpha`` (voxels along each light ray, default 256), ``occupancy`` (centre | hit).
Only on the ``vsv`` view (dsm.maps.vsv).
"""
from dataclasses import dataclass, field

import drjit as dr

from ..maps.vsv import MAX_ALPHA, OCCUPANCY, voxel_lit
from .base import fixed_needs, no_shift

NAME = "vsv"
SOURCE = "Wyman 2011; Dou et al. 2014 sec. 3.3"
NEEDS = frozenset()
USES_PLANE = False
VIEWS = ("vsv",)      # reads a voxelized shadow volume's grid, no depth map
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """The grid's alpha resolution and occupancy rule."""
    alpha: int = field(default=256, metadata={"doc": "voxels along each light ray (the grid's alpha axis)",
                                              "min": 1, "max": MAX_ALPHA})
    occupancy: str = field(default="centre", metadata={"doc": "a voxel's state: its centre's, or occluded when it "
                                                              "holds the hit", "choices": OCCUPANCY})


def margin(rx, tap, p):
    """First occluded voxel of the tap's column less the receiver's own voxel, less 1/2 (lit where >= 0)."""
    return voxel_lit(dr.floor(rx.depth * p.alpha), tap.z1 * p.alpha, p.alpha, p.occupancy)


shift = no_shift
