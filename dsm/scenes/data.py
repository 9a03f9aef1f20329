"""A loaded scene (SceneData): the Mitsuba scene, its sensor, shape names, lights and bounds."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import exact_frame
from ..core.types import LightSpec
from .geometry import make_mesh
from .params import ORIGIN


def scale_light(light: LightSpec, s: float, offset=ORIGIN) -> LightSpec:
    """A light given relative to the scene: positions scaled by ``s``, then moved by ``offset``."""
    if light.position is None:
        return light
    from dataclasses import replace
    t = tuple(float(c) for c in offset)
    return replace(light, position=tuple(s * c + o for c, o in zip(light.position, t)),
                   target=None if light.target is None else tuple(s * c + o for c, o in zip(light.target, t)),
                   size=tuple(s * c for c in light.size))


@dataclass
class SceneData:
    """A loaded scene: Mitsuba scene and sensor, shape names, own lights, bounds, and the config's scale and offset."""
    label: str
    scene: object                  # mi.Scene
    sensor: object                 # mi.Sensor
    shape_names: list              # by shape_index (order of scene.shapes())
    own_lights: list               # the scene's lights (LightSpec), used by [[light]] type = "scene"
    bbox: tuple                    # (min, max) numpy
    scale: float                   # multiplies the config's light positions
    notes: list = field(default_factory=list)
    closed_override: tuple = ()    # (shape name, closed) pairs from the config
    closed: list = None            # per shape, computed when a culling choice needs it
    closed_reason: list = None
    offset: tuple = ORIGIN         # added to the config's light positions after scaling (translate)
    camera_pose: object = None     # the camera's (position, target, up), float64 (built-ins and mesh files)
    checked: tuple = ()            # shapes the loader already checked (check_mesh), not checked again
    centre: object = None          # the exact frame's origin (dsm.scenes.exact_frame; float64 world), None: the world
    exact_scene: object = None     # the scene in that frame (None: ``scene``)

    @property
    def exact(self):
        """The Mitsuba scene the exact side (G-buffer, reference) is traced in."""
        return self.scene if self.exact_scene is None else self.exact_scene

    def centre_frame(self, shapes64: dict):
        """Trace the exact side in a frame centred on the scene when it sits far from the origin
        (:mod:`dsm.scenes.exact_frame`): ``shapes64`` the world scene's meshes by key, in float64."""
        centre = exact_frame.centre_for(self.bbox)
        if centre is None:
            return
        self.use_exact_scene(centre, _moved_scene(shapes64, centre))

    def use_exact_scene(self, centre: np.ndarray, exact_scene):
        """Trace the exact side in ``exact_scene``: the world scene's shapes, in its order, moved by minus
        ``centre`` (float64, world) before their rounding to float32."""
        ids = [sh.id() for sh in self.scene.shapes()]
        if ids != [sh.id() for sh in exact_scene.shapes()]:
            raise RuntimeError(f"scene {self.label!r}: the centred frame's shapes are not in the world's order")
        self.centre, self.exact_scene = centre, exact_scene

    @property
    def diagonal(self) -> float:
        """The length of the scene's bounding-box diagonal (world units)."""
        return float(np.linalg.norm(self.bbox[1] - self.bbox[0]))

    def lights_for(self, specs) -> list:
        """The lights of the ``[[light]]`` specs that apply here: the scene's own, its emitters, or scaled."""
        out = []
        for spec in specs:
            if not spec.applies_to(self.label):
                continue
            if spec.type == "scene":
                out += self.own_lights
            elif spec.type == "area" and spec.shape == "emitter":
                from .emitters import emitter_lights
                out += emitter_lights(self.scene, spec)     # the scene's own luminaires, as they are
            else:
                out.append(scale_light(spec, self.scale, self.offset))
        return out


def _moved_scene(shapes64: dict, centre: np.ndarray):
    """A Mitsuba scene of ``shapes64`` {key: (vertices (n, 3) float64 world, faces)} moved by
    minus ``centre`` in float64, then rounded to float32; the keys (and so the shapes' order)
    those of the world scene's dict."""
    import mitsuba as mi
    d = {"type": "scene"}
    for name, (v, f) in shapes64.items():
        d[name] = make_mesh(name, np.asarray(v, np.float64) - centre, f)
    return mi.load_dict(d, optimize=False)


def finish(label, scene, own_lights, scale, notes=()):
    """SceneData of a loaded Mitsuba scene: its bounds, shape names and first sensor."""
    bb = scene.bbox()
    bbox = (np.array(bb.min, float).ravel(), np.array(bb.max, float).ravel())
    names = [sh.id() or f"shape{i}" for i, sh in enumerate(scene.shapes())]
    if not scene.sensors():
        raise ValueError(f"scene {label!r} has no sensor")
    return SceneData(label, scene, scene.sensors()[0], names, list(own_lights), bbox, scale, list(notes))
