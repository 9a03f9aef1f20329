"""Distance-scaled normal bias: a normal offset that grows with the receiver's distance to the camera.

An approximation of Unreal Engine 5's virtual shadow maps' receiver bias. UE documents
``r.Shadow.Virtual.NormalBias`` (default 0.5) as the "receiver offset along surface normal for
shadow lookup, scaled by distance to camera" (Unreal Engine 5 documentation, Virtual Shadow
Maps); UE's renderer divides the console value by 1000 before its shader reads it
(``GetNormalBiasForShader``, VirtualShadowMapArray.cpp). Here the lookup point moves along the
receiver's geometric normal by

    offset = max(min_offset, normal_bias / 1000 * d_cam * tan(fov_x / 2))

``d_cam`` the receiver's view depth along the camera's axis and ``fov_x`` the camera's
horizontal field of view (``d_cam tan(fov_x / 2)``: half the width of the view at the receiver,
so the offset is a fixed fraction of the screen at any distance); then ``d' <= z1(p') + bias``
as :mod:`normal_offset`. The scaling by view depth times tan(fov_x / 2) is this kit's reading
of the documented "scaled by distance to camera", not checked against UE's shader source.
Not simulated: the virtual pages and clipmap levels (each level's own texel size), the
per-page depth bias, SMRT's screen ray and its slope extrapolation: the map is the kit's
single map (or its cascades), so this is the bias term alone, measured on the kit's maps.

Needs the camera that sees the receivers (``dsm run`` and :func:`dsm.pipeline.receivers` give it
for a perspective sensor); without one the lookup raises ValueError.

Parameters: ``normal_bias`` (UE's console value, default 0.5), ``min_offset`` (length, default 0:
UE's floor is 0.02 cm, a unit this kit's scenes do not have), ``bias`` (length, default 0).
"""
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

from ..core.types import Length
from .base import fixed_needs

NAME = "distance_normal"
SOURCE = "Unreal Engine 5 virtual shadow maps, r.Shadow.Virtual.NormalBias (approximation)"
NEEDS = frozenset()
USES_PLANE = False
READS_CAMERA = True          # the receivers' camera (Receiver.camera): dsm tune's light samples have none
VIEWS = None          # every view but the exclusive ones (a depth-map scheme)
needs = fixed_needs(NEEDS)


@dataclass(frozen=True)
class Params:
    """Distance-scaled normal bias's parameters: UE's ``normal_bias``, its floor ``min_offset`` and a depth ``bias``."""
    normal_bias: float = field(default=0.5, metadata={"doc": "r.Shadow.Virtual.NormalBias: offset / 1000 of "
                                                             "the view's half width at the receiver", "min": 0.0})
    min_offset: Length = field(default=Length(0.0, "world"), metadata={"doc": "smallest offset", "min": 0.0})
    bias: Length = field(default=Length(0.0, "world"), metadata={"doc": "depth offset added to z1"})


def offset_world(rx, p):
    """The normal offset of each receiver (world units): max(min_offset, normal_bias / 1000 d_cam tan(fov_x / 2))."""
    cam = rx.camera
    if cam is None:
        raise ValueError("distance_normal needs the camera that sees the receivers (dsm run and "
                         "dsm.pipeline.receivers give it for a perspective sensor)")
    o, f = (mi.Vector3f(*(float(c) for c in a)) for a in (cam.origin, cam.forward))
    d_cam = dr.dot(rx.p_world - o, f)
    return dr.maximum(p.min_offset, p.normal_bias * dr.opaque(mi.Float, 1e-3 * cam.tan_x) * d_cam)


def shift(rx, p):
    """The receiver moved along its geometric normal by :func:`offset_world`."""
    return rx.moved(rx.p_world + rx.n_world * offset_world(rx, p))


def margin(rx, tap, p):
    """z1(p') + bias - d' at the moved receiver, in view depth units."""
    return tap.z1 + p.bias - rx.depth
