"""Dou et al.'s adaptive voxel choice for voxelized shadow volumes (JCGT 2014, section 3.3).

Algorithm 2 and Listing 3 of Dou et al., on Wyman 2011's grid (dsm.maps.vsv). The light ray through the centre of the receiver's cell (its theta and phi) meets the receiver's
tangent plane at F', the potential occluder. F' is moved toward the light by the constant epsilon
``K * sceneScale`` (Listing 3's "constant epsilon based on scene scale"), then its alpha voxel
V2 is found: when F' lies behind or on V2's centre (farther from the light), V2 is tested, else
the adjacent voxel toward the light, V3. Under the centre occupancy (a voxel's state is its
centre's) the chosen voxel's centre never lies behind a planar receiver, so planes are free of
acne; under ``occupancy = "hit"`` V2 holds the surface and is occluded, and half the receivers
still read it (the rule needs the centre's state, as Dou et al.'s figure 5 draws it).

Where the ray does not meet the plane in front of the light, the plain voxel test of the
receiver is used (``n_plane_fallback``). Parameters: ``K`` (default 0.0001, the paper's),
``alpha``, ``occupancy``. Only on the ``vsv`` view.
"""
from dataclasses import dataclass, field

import drjit as dr

from ..maps.vsv import voxel_lit
from .vsv import Params as GridParams
from .base import fixed_needs, no_shift

NAME = "vsv_adaptive"
SOURCE = "Dou et al. 2014 sec. 3.3, Algorithm 2"
NEEDS = frozenset()
USES_PLANE = True     # the cell's ray against the receiver's tangent plane (lookup.plane_fallbacks)
VIEWS = ("vsv",)
READS_CAMERA = False
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params(GridParams):
    """Epsilon as a fraction of the scene's diagonal, the grid's alpha resolution and occupancy rule."""
    K: float = field(default=1e-4, metadata={"doc": "epsilon toward the light as a fraction of the scene's diagonal",
                                             "min": 0.0})


def chosen_voxel(rx, tap, p):
    """Algorithm 2's voxel: F''s (V2) when F' is behind or on V2's centre, else the one toward the light (V3)."""
    view = tap.view
    o, d = view.ray_at(tap.cu_map, tap.cv_map, tap.face)
    den = dr.dot(d, rx.n_world)
    t = dr.dot(rx.p_world - o, rx.n_world) / dr.select(den != 0, den, 1.0)
    s_prime = view.depth(o + d * (t - p.K * rx.scene_scale)) * p.alpha      # F' moved epsilon toward the light
    met = (den != 0) & (t > 0) & dr.isfinite(s_prime)
    k2 = dr.floor(s_prime)
    k = dr.select(s_prime >= k2 + 0.5, k2, k2 - 1.0)
    return dr.select(met, k, dr.floor(rx.depth * p.alpha))


def margin(rx, tap, p):
    """The chosen voxel tested in the tap's column: first occluded voxel less it, less 1/2 (lit where >= 0)."""
    return voxel_lit(chosen_voxel(rx, tap, p), tap.z1 * p.alpha, p.alpha, p.occupancy)


shift = no_shift
