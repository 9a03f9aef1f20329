"""A :class:`Receiver`: what a scheme may read about the shaded points in one view (position,
normal, depth and map position, texel world size there, the camera that sees them)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..scenes.camera import Camera


@dataclass
class Receiver:
    """What a scheme may read about the shaded points; names carry their frame."""
    view: object
    p_world: object      # mi.Point3f, world
    n_world: object      # geometric normal (the visible side), world
    to_light: object     # unit vector toward the light, world
    depth: object        # depth in the view's one depth function (world units)
    u_map: object        # map position, texel units of the receiver's face
    v_map: object
    face: object         # mi.UInt32, the view's face (map) the receiver falls in
    texel_world: object  # world width of one texel at the receiver
    scene_scale: object  # the scene's bounding-box diagonal (opaque scalar)
    camera: Camera | None = None  # the pinhole camera that sees the receivers; None: not known

    @staticmethod
    def make(view, p_world, n_world, scene_scale: float, camera=None) -> "Receiver":
        """The Receiver of world points ``p_world`` (normals ``n_world``) in ``view``; ``scene_scale``: the
        diagonal; ``camera``: the camera that sees them (schemes scaled by the distance to it read it)."""
        u, v, face = view.project(p_world)
        return Receiver(view, p_world, n_world, view.to_light(p_world), view.depth(p_world), u, v, face,
                        view.texel_world(p_world), dr.opaque(mi.Float, scene_scale), camera)

    def moved(self, p2_world) -> "Receiver":
        """The same receiver looked up from another point (normal offset)."""
        u, v, face = self.view.project(p2_world)
        return dataclasses.replace(self, p_world=p2_world, depth=self.view.depth(p2_world), u_map=u, v_map=v,
                                   face=face)
