"""Camera poses and sensors: the [camera] keys over a scene's own pose, clip planes, Mitsuba sensor dicts."""
from __future__ import annotations

import math
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from ..core.types import ConfigError
from .params import ORIGIN


def look_at_sensor(origin, target, up, fov, width, height, near=None, far=None, camera=None, source="<config>"):
    """A perspective sensor dict. Clip planes follow the scene's scale (Mitsuba's default near clip is
    0.01 world units): ``near`` default 1/1000 of the distance to the target, ``far`` 1000 times it.
    Clips that cross are a ConfigError naming the [camera] key of ``camera`` that set one alone."""
    import mitsuba as mi
    dist = float(np.linalg.norm(np.subtract(origin, target)))
    near = dist * 1e-3 if near is None else float(near)
    far = dist * 1e3 if far is None else float(far)
    with np.errstate(over="ignore"):             # a far beyond float32 is inf: still beyond near
        crossed = not np.float32(near) < np.float32(far)   # Mitsuba compares them in float32
    if crossed:                                  # else Mitsuba's RuntimeError, with no key to name
        raise clip_error(near, far, camera, source)
    return {"type": "perspective", "fov": fov, "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, origin)),
                                                       target=list(map(float, target)),
                                                       up=list(map(float, up))),
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height)}}


def sensor_at(base, origin, target, up):
    """A sensor at a pose with the base camera's (a :class:`Camera`) film, field of view and clip planes."""
    fov = math.degrees(2 * math.atan(base.tan_x))
    return mi.load_dict(look_at_sensor(origin, target, up, fov, base.width, base.height, base.near, base.far))


def clip_error(near, far, camera, source="<config>"):
    """The error for a near clip not below the far clip: one of them given alone in [camera]."""
    given = {k for k in ("near", "far") if camera is not None and getattr(camera, k) is not None}
    if given == {"far"}:
        return ConfigError(source, "camera.far", f"{camera.far:g} is not beyond the near clip it goes with "
                           f"({near:.3g} world units: the scene's, or 1/1000 of the camera's distance to its "
                           "target); give a larger far, or camera.near below it")
    if given == {"near"}:
        return ConfigError(source, "camera.near", f"{camera.near:g} is not below the far clip it goes with "
                           f"({far:.3g} world units: the scene's, or just beyond its farthest point); give a "
                           "smaller near, or camera.far above it")
    return ConfigError(source, "camera", f"the near clip ({near:.3g}) is not below the far clip ({far:.3g})",
                       ("near", "far"))


def far_bound(origin, target, bbox_min, bbox_max) -> float:
    """A sensible far clip: the view depth of the scene's farthest bounding-box corner (a bound on the
    farthest receiver), 1 % beyond it."""
    fwd = np.subtract(target, origin).astype(float)
    fwd /= np.linalg.norm(fwd)
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    return max(float(((corners - np.asarray(origin, float)) @ fwd).max()), 1e-30) * 1.01


NEAR_MIN = 1e-12     # the smallest near clip, relative to the camera's distance to its target (1e-19 fails)


def posed_camera(default, camera, scale=1.0, offset=ORIGIN, source="<config>"):
    """(origin, target, up, fov, near, far) of a scene's camera: the scene's own ``default`` pose
    (origin, target, up, fov, near or None, far or None, world units) with the [camera] keys that
    are given (``camera``: a CameraSpec or None) scaled by ``scale`` and moved by ``offset`` as the
    config's light positions are. A pose that cannot be looked from (the position on the target,
    the up along the view) is a ConfigError of ``source`` naming the [camera] key."""
    o, t, up, fov, near, far = default
    if camera is not None:
        off = np.asarray(offset, float)
        if camera.position is not None:
            o = np.asarray(camera.position, float) * scale + off
        if camera.target is not None:
            t = np.asarray(camera.target, float) * scale + off
        up = camera.up if camera.up is not None else up
        fov = camera.fov if camera.fov is not None else fov
        near = camera.near * scale if camera.near is not None else near
        far = camera.far * scale if camera.far is not None else far
    key = "target" if camera is not None and camera.target is not None else "position"
    if np.allclose(np.asarray(o, float), np.asarray(t, float)):
        raise ConfigError(source, f"camera.{key}", f"the camera's position {tuple(float(c) for c in o)} equals "
                          f"its target (the scene's own pose, where the [camera] key is not given)")
    fwd, upv = np.subtract(t, o).astype(float), np.asarray(up, float)
    dist = float(np.linalg.norm(fwd))
    if camera is not None and camera.near is not None and near < NEAR_MIN * dist:
        raise ConfigError(source, "camera.near", f"{camera.near:g} is below {NEAR_MIN:g} of the camera's distance "
                          f"to its target ({dist / scale:g}): the float32 projection of the camera's rays breaks "
                          f"down there (no ray would reach the scene); give at least {NEAR_MIN * dist / scale:.3g}")
    if np.linalg.norm(np.cross(fwd, upv)) <= 1e-6 * np.linalg.norm(fwd) * np.linalg.norm(upv):
        raise ConfigError(source, "camera.up", f"{tuple(float(c) for c in up)} is along the view direction "
                          f"(target - position = {tuple(float(c) for c in fwd)}); give an up across it")
    return np.asarray(o, float), np.asarray(t, float), tuple(float(c) for c in up), float(fov), near, far


def reposed_sensor(sensor, camera, bbox, source="<config>"):
    """An XML scene's sensor with the [camera] pose: its film (size) kept, the keys given replaced.
    A sensor that is not perspective is refused (the pose keys aim a pinhole camera: an
    orthographic sensor would become a perspective one)."""
    import mitsuba as mi
    kind = projection(sensor)
    if kind != "perspective":
        given = next((k for k in ("position", "target", "up", "fov", "near", "far") if getattr(camera, k, None) is not None),
                     "position")
        raise ConfigError(source, f"camera.{given}", f"the scene's sensor is {kind}: [camera] re-aims a perspective "
                          "camera only, and would turn it into one; remove the [camera] pose keys (resolution keeps "
                          "the projection), or give the scene a perspective sensor")
    params = mi.traverse(sensor)
    m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    o = m[:3, 3]
    fwd, up = m[:3, 2], m[:3, 1]
    near = float(np.ravel(params["near_clip"])[0]) if "near_clip" in params else None
    far = float(np.ravel(params["far_clip"])[0]) if "far_clip" in params else None
    fov = float(params["x_fov"][0]) if "x_fov" in params else 40.0
    # the XML's target: the point of its view axis nearest the scene's centre (a new position looks there)
    centre = 0.5 * (np.asarray(bbox[0], float) + np.asarray(bbox[1], float))
    reach = float((centre - o) @ fwd)
    reach = reach if reach > 0 else float(np.linalg.norm(np.asarray(bbox[1], float) - np.asarray(bbox[0], float)))
    o2, t2, up2, fov2, near2, far2 = posed_camera((o, o + fwd * reach, up, fov, near, far), camera, source=source)
    if camera.far is None and (camera.position is not None or camera.target is not None):
        far2 = far_bound(o2, t2, *bbox)
    W, H = (int(x) for x in sensor.film().size())
    d = look_at_sensor(o2, t2, up2, fov2, W, H, near2 if near2 is not None else None, far2, camera, source)
    d["fov_axis"] = "x"
    return mi.load_dict(d)


def projection(sensor) -> str:
    """A sensor's projection: "perspective" (it has a field of view), "orthographic", or its class name."""
    import mitsuba as mi
    if "x_fov" in mi.traverse(sensor):
        return "perspective"
    name = type(sensor).__name__.lower()
    return "orthographic" if "ortho" in name or "ortho" in str(sensor).lower()[:40] else name


def resized_sensor(sensor, width, height):
    """The sensor at width x height: the same projection (perspective or orthographic), transform,
    field of view and clips."""
    import mitsuba as mi
    params = mi.traverse(sensor)
    m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
    kind = projection(sensor)
    d = {"type": kind if kind == "orthographic" else "perspective", "to_world": mi.ScalarTransform4f(m),
         "film": {"type": "hdrfilm", "width": int(width), "height": int(height)}}
    if "x_fov" in params:
        d["fov"] = float(params["x_fov"][0])
        d["fov_axis"] = "x"
    for k in ("near_clip", "far_clip"):
        if k in params:
            d[k] = float(np.ravel(params[k])[0])
    return mi.load_dict(d)


@dataclass
class Camera:
    """A pinhole camera in world space (float64): the sensor's pose, field of view and clip planes."""
    origin: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    left: np.ndarray
    tan_x: float        # tan of half the horizontal field of view
    tan_y: float
    near: float
    far: float
    width: int
    height: int

    @staticmethod
    def from_sensor(sensor) -> "Camera":
        """The Camera of a Mitsuba sensor: its world pose, horizontal fov (default 40), clip planes and film size."""
        m = np.array(sensor.world_transform().matrix.numpy(), float).reshape(4, 4)
        params = mi.traverse(sensor)
        fov = float(params["x_fov"][0]) if "x_fov" in params else 40.0
        W, H = (int(x) for x in sensor.film().size())
        near = float(np.ravel(params["near_clip"])[0]) if "near_clip" in params else 1e-2
        far = float(np.ravel(params["far_clip"])[0]) if "far_clip" in params else 1e4
        unit = lambda v: v / np.linalg.norm(v)
        tx = math.tan(math.radians(fov) / 2)
        return Camera(m[:3, 3].copy(), unit(m[:3, 2]), unit(m[:3, 1]), unit(m[:3, 0]), tx, tx * H / W, near, far, W, H)

    def depth(self, p: np.ndarray) -> np.ndarray:
        """View depth (along the camera's axis) of world points (n, 3), float64."""
        return (np.asarray(p, float).reshape(-1, 3) - self.origin) @ self.forward

    def frustum(self, d0: float, d1: float) -> np.ndarray:
        """The 8 corners of the view frustum between view depths d0 and d1 (corner i: bit 0 left/right,
        bit 1 down/up, bit 2 near/far)."""
        out = []
        for i in range(8):
            d = (d0, d1)[i >> 2 & 1]
            sx, sy = (-1.0, 1.0)[i & 1], (-1.0, 1.0)[i >> 1 & 1]
            out.append(self.origin + self.forward * d + self.left * (sx * self.tan_x * d) + self.up * (sy * self.tan_y * d))
        return np.array(out)

    def pixel_width(self, p: np.ndarray) -> np.ndarray:
        """World width of each point's camera pixel across its ray: the square root of the pixel's
        solid angle, (2 tan_x / W)^2 cos^3(alpha), times the distance (a texel's ``texel_world`` is
        measured the same way, so their ratio is texels per pixel whatever the surface's slope)."""
        q = np.asarray(p, float).reshape(-1, 3) - self.origin
        dist = np.linalg.norm(q, axis=1)
        cos_a = (q @ self.forward) / dist
        return (2.0 * self.tan_x / self.width) * cos_a ** 1.5 * dist

    def pixel_area(self, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """World area of each receiver's camera pixel footprint on its surface (p, n: (k, 3)):
        the pixel's solid angle (2 tan_x / W)^2 cos^3(alpha) times distance^2 over |cos| to the normal."""
        q = np.asarray(p, float) - self.origin
        dist = np.linalg.norm(q, axis=1)
        cos_a = (q @ self.forward) / dist
        omega = (2.0 * self.tan_x / self.width) ** 2 * cos_a ** 3
        cos_n = np.abs((np.asarray(n, float) * q).sum(1)) / dist
        return omega * dist ** 2 / np.maximum(cos_n, 1e-12)
