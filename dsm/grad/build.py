"""The map build with attached intersections: depths that carry gradients.

The kit's build (:mod:`dsm.maps.shadowmap`) casts with ``ray_intersect_preliminary``, whose ``t``
is detached, and stays as it is (its speed is unchanged: nothing here runs unless a gradient is
asked). Here each texel's ray goes through ``scene.ray_intersect``, which recomputes the hit on
its triangle from the (possibly attached) vertex buffer and the (attached) ray: the hit point
``si.p``, hence the depth in the view's one depth function, follows the occluder and the light.
The hit's shape and triangle are kept for the antialiased map (:mod:`dsm.grad.antialias`).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..maps.shadowmap import ShadowMap
from ..scenes import spawn


@dataclass
class AttachedMap:
    """A map built with attached intersections: the kit's ShadowMap (z1 attached), and per texel
    the hit's triangle index within its shape (0xFFFFFFFF on a miss)."""
    smap: ShadowMap
    prim: object


def build(scene, view) -> AttachedMap:
    """The first layer of ``view``'s map over ``scene``, z1 differentiable (rays through texel centres)."""
    rays = view.texel_rays(0, view.n_texels)
    si = scene.ray_intersect(rays, ray_flags=mi.RayFlags.All, coherent=spawn.COHERENT)
    valid = si.is_valid()
    table = spawn.shape_table(scene, force=True)
    ids = dr.reinterpret_array(mi.UInt32, si.shape)
    known = valid & (ids < dr.width(table))
    shape = dr.select(known, dr.gather(mi.UInt32, table, ids, known), spawn.NO_SHAPE)
    z1 = dr.select(valid, view.depth(si.p), view.far_o)
    prim = dr.select(valid, si.prim_index, spawn.NO_SHAPE)
    # evaluated here (AD keeps its graph): the build, the edge weights and the lookup are separate
    # kernels, not one whose LLVM compile takes a minute (the directional light's, measured)
    dr.eval(z1, shape, prim)
    return AttachedMap(ShadowMap(view, z1, shape), prim)
