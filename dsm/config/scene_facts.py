"""What a Mitsuba scene file holds that decides its experiment (``dsm run SCENE.xml``): its lights,
which shapes are closed, how far it sits from the origin, and its receivers' footprints in each
light's map as the camera sees them (one G-buffer at the file's film, a map of ``MEASURE_R`` texels
a side per light and view). The rules that turn these facts into a config are
:mod:`dsm.config.derive`; nothing here decides.

Footprints: a receiver is a hit pixel facing the light (inside a positional light's view). Its
camera pixel's width across the camera ray (:meth:`dsm.scenes.camera.Camera.pixel_width`) over its
texel's width across the light ray (the view's ``texel_world``, the kit's one meaning of a texel)
is its footprint in texels: the texels one pixel spans. Both are widths across the rays, so a
surface's slope (projective aliasing, which no resolution or cascade removes) does not enter. The
facts are measured in the exact frame (:mod:`dsm.scenes.exact_frame`): a scene far from the origin
has the footprints it has at the origin; only its distance from the origin differs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mitsuba as mi
import numpy as np

from .. import lights as light_types
from ..core.types import ConfigError
from ..scenes import exact_frame, gbuffer
from ..scenes.camera import Camera
from ..scenes.closedness import shape_closedness
from ..scenes.emitters import describe_light, emitter_lights, lights_of
from ..scenes.load import load
from ..scenes.spec import parse_scene

MEASURE_R = 1024                                  # texels a side of the maps the footprints are measured on
POINT_VIEWS = ("dual_paraboloid", "cube")        # a point light's views, both measured and both derived
AREA_EMITTER = {"type": "area", "shape": "emitter"}


@dataclass(frozen=True)
class ViewFacts:
    """One light's view at MEASURE_R: its receivers' footprints (texels per pixel, linear) and depth range."""
    light: str                     # the light's label (``0:directional``, ``area 1``)
    light_type: str
    kind: str                      # the view kind (orthographic, perspective, cube, ...)
    footprint_texels: np.ndarray   # per receiver: its pixel's width in texels of this view at MEASURE_R
    texel_world: np.ndarray        # per receiver: one texel's width at MEASURE_R (world units)
    near: float                    # the view's depth range (world units, its one depth function)
    far: float


@dataclass(frozen=True)
class SceneFacts:
    """The measured quantities behind every rule of :mod:`dsm.config.derive`."""
    path: Path
    film: tuple                    # (width, height) of the file's sensor
    delta_lights: tuple            # LightSpecs of the point, spot and directional emitters
    area_lights: tuple             # LightSpecs of the area emitters (one per luminaire)
    default_light: str             # '' or the light the kit adds to a scene without emitters, in words
    closed: tuple                  # names of the closed meshes (wound outward: a solid culling may use)
    open: tuple                    # (name, why) of the others
    analytic: tuple                # names of non-mesh shapes (caster shrinking cannot move them)
    thinnest_closed: float         # the smallest box extent of a closed mesh (world; inf without one)
    max_abs_coordinate: float      # the scene's largest |coordinate| (world, float64)
    diagonal: float
    views: tuple                   # ViewFacts per light and view


def measure(path) -> SceneFacts:
    """The facts of the Mitsuba scene file ``path`` (a ConfigError naming the file where it cannot be
    used). Needs a Mitsuba variant (``env.use_variant``)."""
    path = Path(path).resolve()
    spec = parse_scene({"file": str(path)}, str(path), "scene", path.parent)[0]
    sd = load(spec)
    if "x_fov" not in mi.traverse(sd.sensor):
        raise ConfigError(str(path), "scene.file", f"its first sensor is not a perspective camera: a derived "
                          "experiment reads the pixels' footprints of a pinhole camera; write a config instead "
                          "(docs/config.md)", ("perspective",))
    delta, _ = lights_of(sd.scene)
    area = emitter_lights(sd.scene, light_types.get("area").parse(dict(AREA_EMITTER), str(path), "light"))
    default = "" if delta or area else sd.own_lights[0]
    closed, open_, analytic, thinnest = _closedness(sd.scene, sd.shape_names)
    lo, hi = (np.asarray(b, np.float64) for b in sd.bbox)
    views = _footprints(sd, (default,) if default else tuple(delta) + tuple(area))
    return SceneFacts(path, tuple(int(x) for x in sd.sensor.film().size()), tuple(delta), tuple(area),
                      describe_light(default) if default else "", closed, open_, analytic, thinnest,
                      float(np.max(np.maximum(np.abs(lo), np.abs(hi)))), sd.diagonal, views)


def _closedness(scene, names) -> tuple:
    """(closed mesh names, (open name, why) pairs, analytic shape names, thinnest closed box extent)."""
    closed, open_, analytic, thinnest = [], [], [], np.inf
    for name, shape in zip(names, scene.shapes()):
        if not shape.is_mesh():
            analytic.append(name)
        ok, why = shape_closedness(shape)
        if ok and "wound inward" not in why:     # a room's walls: culling treats them as open
            closed.append(name)
            bb = shape.bbox()
            thinnest = min(thinnest, float(np.min(np.array(bb.max, float).ravel() - np.array(bb.min, float).ravel())))
        else:
            open_.append((name, why))
    return tuple(closed), tuple(open_), tuple(analytic), float(thinnest)


def _footprints(sd, lights) -> tuple:
    """ViewFacts of every light's views, measured on the G-buffer of the scene's own camera."""
    centre = sd.centre if sd.centre is not None else np.zeros(3)
    sensor = sd.sensor if sd.centre is None else exact_frame.sensor_in(sd.sensor, centre, sd.camera_pose)
    w, h = (int(x) for x in sensor.film().size())
    gb = gbuffer.cast(sd.exact, sensor, w, h)
    cam = Camera.from_sensor(sensor)
    hit = gb.hit
    p = np.stack([np.asarray(c, np.float64) for c in (gb.si.p.x.numpy(), gb.si.p.y.numpy(), gb.si.p.z.numpy())], 1)[hit]
    n = np.stack([np.asarray(c, np.float64) for c in (gb.n.x.numpy(), gb.n.y.numpy(), gb.n.z.numpy())], 1)[hit]
    bbox = exact_frame.bbox_in(sd.bbox, centre)
    out = []
    for i, light in enumerate(lights):
        light_x = exact_frame.light_in(light, centre)
        module = light_types.get(light.type)
        facing = p[_facing(light_x, module.POSITIONAL, p, n)]
        pts = mi.Point3f(*(facing[:, k].astype(np.float32) for k in range(3)))
        for kind in module.views(POINT_VIEWS, light.shape):
            if not len(facing):          # nothing faces this light: no footprint (zero-sized kernels fail)
                out.append(ViewFacts(f"{i}:{light.label or light.type}", light.type, kind, np.zeros(0), np.zeros(0),
                                     math.nan, math.nan))
                continue
            view = module.make_view(light_x, MEASURE_R, facing, bbox, kind, None, sensor, 1.0)
            keep = view.inside(pts).numpy().astype(bool) if module.POSITIONAL else np.ones(len(facing), bool)
            tw = np.asarray(view.texel_world(pts).numpy(), np.float64)[keep]
            pw = cam.pixel_width(facing[keep])
            out.append(ViewFacts(f"{i}:{light.label or light.type}", light.type, kind, pw / tw, tw,
                                 float(view.near), float(view.far)))
    return tuple(out)


def _facing(light, positional: bool, p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Which receivers' camera-side normals face the light (toward its position, or against its direction)."""
    if positional:
        to_light = np.asarray(light.position, np.float64) - p
    else:
        to_light = -np.asarray(light.direction, np.float64)[None, :]
    return (n * to_light).sum(1) > 0
