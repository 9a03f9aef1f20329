"""G-buffer: one primary hit per camera pixel, once per scene/camera.

Rays go through pixel centres. Normals are oriented toward the camera (the visible side),
so "faces the light" means the side the camera sees is lit.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from . import spawn
from .camera import Camera
from .spawn import COHERENT


@dataclass
class GBuffer:
    """The primary hit per camera pixel: interaction, position, normals toward the camera, shape and hit mask."""
    width: int
    height: int
    si: object            # mi.SurfaceInteraction3f of every pixel (for robust spawns)
    p: object             # mi.Point3f
    n: object             # geometric normal, toward the camera
    ns: object            # shading normal, toward the camera
    shape: object         # mi.UInt32 index into scene.shapes(); 0xFFFFFFFF on a miss
    hit: np.ndarray       # bool per pixel
    ms: float = 0.0
    camera: Camera | None = None  # the sensor's pinhole camera; None: not a perspective sensor


def primary_hits(scene, sensor, width: int, height: int, pixels):
    """(ray, preliminary intersection, surface interaction) of the camera rays through the
    centres of ``pixels`` (mi.UInt32 indices y * width + x) of a width x height image."""
    x, y = mi.Float(pixels % width) + 0.5, mi.Float(pixels // width) + 0.5
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / width, y / height), mi.Point2f(0.5, 0.5))
    pi = scene.ray_intersect_preliminary(ray, coherent=COHERENT)   # a pixel's hit, whatever its packet
    return ray, pi, pi.compute_surface_interaction(ray)


def cast(scene, sensor, width: int, height: int) -> GBuffer:
    """The G-buffer of every pixel of a width x height image."""
    ray, pi, si = primary_hits(scene, sensor, width, height, dr.arange(mi.UInt32, width * height))
    toward_cam = -ray.d
    n = mi.Vector3f(si.n) * dr.sign(dr.dot(si.n, toward_cam))
    ns = mi.Vector3f(si.sh_frame.n) * dr.sign(dr.dot(si.sh_frame.n, toward_cam))
    valid = si.is_valid()
    shape = spawn.hit_shape(pi, valid, spawn.shape_table(scene))
    dr.eval(si, n, ns, shape)
    return GBuffer(width, height, si, mi.Point3f(si.p), n, ns, shape, valid.numpy().astype(bool))
