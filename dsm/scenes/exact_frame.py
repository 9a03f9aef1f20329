"""The frame the exact side is traced in: centred on the scene when the scene sits far from the origin.

An engine renders a scene at 1e6 from the origin in float32 world coordinates, and the kit
simulates that for the map. The exact side (the G-buffer's hit points and the reference's shadow
rays) must not inherit those roundings: at 1e6 a float32 step is 0.06 and the spawn bound of a
hit there (:mod:`dsm.scenes.spawn`, 32 u |p|) is 1.9 units, more than a 1-unit box. So, for a scene
whose bounding box lies farther from the origin than ``FAR_RATIO`` times its diagonal, the kit
builds a second Mitsuba scene of the same shapes, in the same order, with every vertex moved by
minus the scene's centre in float64 before rounding to float32 (the built-ins' and mesh files'
vertices are taken in float64 before their ``translate``), and traces the G-buffer and the
reference there; the camera's and the lights' positions move by the same float64 offset. Hit
points and spawn bounds are then those of a scene at the origin. A receiver's world position,
which the map's lookup reads, is its exact-frame position plus the centre in float64, rounded
to float32: the true surface point as an engine holding world positions in float32 has it.

Nearer scenes (and XML scenes, whose vertices are float32 world positions already; and the
plugins' scenes) are traced in world coordinates as they are: the exact frame is the world.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

FAR_RATIO = 16.0      # a bounding box farther than this many diagonals from the origin: a centred frame


def centre_for(bbox) -> np.ndarray | None:
    """The exact frame's origin (float64, world) for a scene of bounding box ``bbox``, or None
    where the scene is near enough to the origin to be traced in world coordinates."""
    lo, hi = (np.asarray(b, np.float64) for b in bbox)
    diag = float(np.linalg.norm(hi - lo))
    far = float(np.max(np.abs(np.concatenate([lo, hi]))))
    if not far > FAR_RATIO * max(diag, np.finfo(np.float32).tiny):
        return None
    return (lo + hi) / 2


def sensor_in(sensor, centre: np.ndarray, pose=None):
    """A perspective sensor like ``sensor`` (film size, field of view, clips) moved by minus
    ``centre``: from ``pose`` (its float64 position, target and up, where known: a small object
    far away would see the float32 rounding of its world matrix as a move and a turn), else from
    its float32 world matrix read in float64."""
    import mitsuba as mi
    w, h = (int(x) for x in sensor.film().size())
    fov = float(mi.traverse(sensor)["x_fov"][0])
    if pose is not None:
        o, target, up = (np.asarray(x, np.float64) for x in pose)
        to_world = mi.ScalarTransform4f().look_at(origin=(o - centre).tolist(), target=(target - centre).tolist(),
                                                  up=up.tolist())
    else:
        m = np.array(sensor.world_transform().matrix, np.float64).reshape(4, 4)
        m[:3, 3] -= centre
        to_world = mi.ScalarTransform4f(m.tolist())
    return mi.load_dict({"type": "perspective", "fov": fov, "fov_axis": "x", "near_clip": float(sensor.near_clip()),
                         "far_clip": float(sensor.far_clip()), "to_world": to_world,
                         "film": {"type": "hdrfilm", "width": w, "height": h}})


def light_in(light, centre: np.ndarray):
    """``light`` (a LightSpec) with its position and target moved by minus ``centre`` (float64)."""
    def move(p):
        return None if p is None else tuple(float(c) for c in np.asarray(p, np.float64) - centre)
    return replace(light, position=move(light.position), target=move(light.target))


def bbox_in(bbox, centre: np.ndarray) -> tuple:
    """A bounding box (min, max) moved by minus ``centre``."""
    return tuple(np.asarray(b, np.float64) - centre for b in bbox)


def to_world(p_exact, centre: np.ndarray):
    """Exact-frame points (mi.Point3f) as float32 world positions: plus ``centre`` in float64,
    rounded once."""
    import mitsuba as mi
    p = np.stack([np.asarray(c, np.float64) for c in (p_exact.x, p_exact.y, p_exact.z)], 1) + centre
    p32 = p.astype(np.float32)
    return mi.Point3f(mi.Float(p32[:, 0]), mi.Float(p32[:, 1]), mi.Float(p32[:, 2]))
