"""The built-in scenes' geometry: triangle meshes in code (z up) at scale 1, their camera and light."""
from __future__ import annotations

import math

import numpy as np

from ..core.types import LightSpec
from ..core.env import meshes_folder
from .files import mesh_arrays
from .geometry import (CROSS_MAX, CROSS_MIN, box, cross_lengths, double_torus, normalize, prism, quad,
                       rotation)

# occluder_mesh's mesh when none is given: the kit's Stanford bunny (its terms: data/meshes/README.md)
DEFAULT_OCCLUDER_MESH = "mitsuba_bunny.ply"
# the occluder scenes' default light: 20 degrees from the vertical toward +x (dsm grad's plate_directional)
OCCLUDER_LIGHT_DEG = 20.0


def _ground(half=4.0):
    return quad([0, 0, 0], [half, 0, 0], [0, half, 0])


def _plane(p):
    """The tilted plane: (shapes, camera, light) at scale 1."""
    rot = rotation([math.cos(math.radians(p.azimuth)), math.sin(math.radians(p.azimuth)), 0], p.tilt)
    v, f = quad([0, 0, 0], [2, 0, 0], [0, 2, 0])
    shapes = {"plane": (v @ rot.T, f)}
    return shapes, ((0.7, -5.0, 5.0), (0, 0, 0)), LightSpec("directional", direction=(0.0, 0.0, -1.0))


def _plane_box(_p):
    """The box on the ground: (shapes, camera, light) at scale 1."""
    shapes = {"ground": _ground(), "box": box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])}
    return shapes, ((5.0, -7.0, 6.0), (0, 0, 0.3)), LightSpec("directional", direction=normalize([-0.4, -0.3, -1]))


def _l_shape(_p):
    """The L-shaped solid over the ground: (shapes, camera, light) at scale 1."""
    # Weiskopf & Ertl 2003, figure 5: an L above the ground, its vertical arm on the right, light from right above
    profile = [(-1, 0.5), (1, 0.5), (1, 2.0), (0.7, 2.0), (0.7, 0.8), (-1, 0.8)]
    shapes = {"ground": _ground(), "l_shape": prism(profile, -0.8, 0.8, fan_center=4)}
    return shapes, ((-2.0, -6.0, 5.0), (0, 0, 0.7)), LightSpec("directional", direction=normalize([-0.35, 0.05, -1]))


def _floating_plate(p):
    """The plate ``p.gap`` above the ground: (shapes, camera, light) at scale 1."""
    shapes = {"ground": _ground(), "plate": quad([0, 0, p.gap], [0.75, 0, 0], [0, 0.75, 0])}
    return shapes, ((3.0, -5.0, 4.0), (0, 0, 0)), LightSpec("directional", direction=normalize([0.2, 0.1, -1]))


def _stacked_plates(p):
    """The two plates at ``p.low`` and ``p.high``: (shapes, camera, light) at scale 1."""
    shapes = {"ground": _ground(), "low": quad([0, 0, p.low], [0.75, 0, 0], [0, 0.75, 0]),
              "high": quad([-0.375, 0, p.high], [0.375, 0, 0], [0, 0.75, 0])}
    # the camera low, to see the ground under the plates, where the leak is; the light straight down
    return shapes, ((2.4, -3.0, 0.8), (0.0, 0.0, 0.1), 40.0), LightSpec("directional", direction=(0.0, 0.0, -1.0))


def _grazing(p):
    """The ground and a box lit at ``p.angle`` from the normal: (shapes, camera, light) at scale 1."""
    t = math.radians(p.angle)
    shapes = {"ground": _ground(), "box": box([-2.3, -0.3, 0.0], [-1.7, 0.3, 0.6])}
    return shapes, ((0.0, -3.0, 8.0), (0, 0, 0)), LightSpec("directional", direction=(math.sin(t), 0.0, -math.cos(t)))


def _room(_p):
    """The closed room around a point light: (shapes, camera, light) at scale 1."""
    walls, wf = box([-3, -3, 0], [3, 3, 3])
    profile = [(-0.4, 0.0), (0.4, 0.0), (0.4, 0.3), (0.0, 1.0), (-0.4, 0.3)]     # a house-shaped prism
    shapes = {"room": (walls, wf[:, ::-1]),                     # closed, facing in
              "cube": box([0.9, 0.6, 0.0], [1.7, 1.4, 0.8]),
              "pillar": box([-1.9, -1.6, 0.0], [-1.4, -1.1, 2.2]),
              "house": prism(profile, -2.2, -1.4, fan_center=2),
              "shelf": quad([-0.6, 1.2, 1.1], [0.6, 0, 0], [0, 0.35, 0])}      # open, floating
    shapes["house"] = (shapes["house"][0] + [-0.2, 0.0, 0.0], shapes["house"][1])
    light = LightSpec("point", position=(0.2, 0.1, 1.8), direction=(0.0, 0.0, -1.0), label="point")
    return shapes, ((2.8, -2.8, 2.7), (-0.6, 0.6, 0.4), 75.0), light


def _double_torus(_p):
    """The double torus over the ground: (shapes, camera, light) at scale 1."""
    # Weiskopf & Ertl 2003, figure 6: the double torus over a plane; tilted so the light from above grazes
    # its far side and sees into both holes (midpoint's self-unshadowing shows at its lower left)
    v, f = double_torus()
    v = v @ rotation([1, 0.3, 0], 20).T + [0.0, 0.0, 0.9]
    shapes = {"ground": _ground(), "double_torus": (v, f)}
    return shapes, ((1.0, -4.5, 3.8), (0, 0, 0.5)), LightSpec("directional", direction=normalize([0.3, -0.2, -1]))


def _long_ground(_p):
    """The long ground lined with posts: (shapes, camera, light) at scale 1."""
    verts, faces = [], []
    for x in np.arange(-90.0, 91.0, 10.0):
        for y in (-4.0, 4.0):
            v, f = box([x - 0.2, y - 0.2, 0.0], [x + 0.2, y + 0.2, 4.0])
            faces.append(f + sum(len(a) for a in verts))
            verts.append(v)
    shapes = {"ground": quad([0, 0, 0], [100.0, 0, 0], [0, 10.0, 0]),
              "posts": (np.vstack(verts), np.vstack(faces))}
    return shapes, ((-99.0, 0.0, 3.0), (-60.0, 0.0, 0.0), 60.0), \
        LightSpec("directional", direction=normalize([0.2, -0.5, -0.6]))


def _terrain(p):
    """The Jacksboro fault terrain at every ``p.stride``-th sample: (shapes, camera, light) at scale 1."""
    from . import terrain
    verts, faces = terrain.mesh(p.stride)
    # a viewer 800 m above the south-west corner looking north-east across the fault, 27
    # degrees down; the sun 20 degrees above the horizon from the south-east
    eye = (-13000.0, -14000.0, 1600.0)
    return {"terrain": (verts, faces)}, (eye, (-8000.0, -9000.0, -2000.0), 60.0), \
        LightSpec("directional", direction=normalize([-0.664, 0.664, -0.342]))


def _occluder_scene(p, occluder):
    """The ground of half side ``p.ground_half`` and ``occluder`` (verts, faces): (shapes, camera, light) at
    scale 1; the camera looks down on the occluder from the side its shadow falls toward (+x: the light's tilt)."""
    top = float(np.max(occluder[0][:, 2]))
    reach = max(p.size, top)
    target = (0.0, 0.0, 0.5 * top)
    camera = (tuple(np.add(target, np.multiply((0.6, -1.0, 0.9), 2.5 * reach))), target)
    t = math.radians(OCCLUDER_LIGHT_DEG)
    light = LightSpec("directional", direction=(math.sin(t), 0.0, -math.cos(t)))
    return {"ground": _ground(p.ground_half), "occluder": occluder}, camera, light


def _occluder_plate(p):
    """A square plate of side ``p.size`` at ``p.height``: (shapes, camera, light) at scale 1."""
    half = 0.5 * p.size
    return _occluder_scene(p, quad([0.0, 0.0, p.height], [half, 0.0, 0.0], [0.0, half, 0.0]))


def _occluder_box(p):
    """A closed box ``p.size`` wide and ``p.box_height`` high, its bottom at ``p.height``: (shapes, camera,
    light) at scale 1."""
    half = 0.5 * p.size
    return _occluder_scene(p, box([-half, -half, p.height], [half, half, p.height + p.box_height]))


def occluder_mesh_vertices(v, size: float, height: float) -> np.ndarray:
    """Vertices ``v`` (n, 3) scaled so their largest extent is ``size``, centred over the origin in x and
    y, their lowest point at ``height`` (float64, world)."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) * (size / float(np.max(hi - lo)))
    return v + np.array([0.0, 0.0, height])


def _occluder_mesh(p):
    """The mesh file ``p.mesh`` (or the kit's bunny) placed by occluder_mesh_vertices: (shapes, camera, light)
    at scale 1."""
    v, f = mesh_arrays(p.mesh or meshes_folder() / DEFAULT_OCCLUDER_MESH)
    return _occluder_scene(p, (occluder_mesh_vertices(v, p.size, p.height), f))


# the geometry of each built-in by name (dsm.scenes.params.BUILTINS: its parameters)
_GEOMETRY = {"plane": _plane, "plane_box": _plane_box, "l_shape": _l_shape, "floating_plate": _floating_plate,
             "stacked_plates": _stacked_plates, "grazing": _grazing, "room": _room, "double_torus": _double_torus,
             "long_ground": _long_ground, "terrain": _terrain, "occluder_plate": _occluder_plate,
             "occluder_box": _occluder_box, "occluder_mesh": _occluder_mesh}


def builtin_geometry(name: str, p):
    """(shapes {name: (verts, faces)}, camera (origin, target), default light) at scale 1."""
    if name not in _GEOMETRY:
        raise KeyError(name)
    return _GEOMETRY[name](p)


def scale_range(name: str, p, shapes=None) -> tuple:
    """The scales at which every triangle of a built-in keeps a float32 normal (see CROSS_MAX);
    ``shapes``: its geometry where the caller has it."""
    shapes = builtin_geometry(name, p)[0] if shapes is None else shapes
    c = np.concatenate([cross_lengths(v, f) for v, f in shapes.values()])
    c = c[c > 0]
    return math.sqrt(CROSS_MIN / c.min()), math.sqrt(CROSS_MAX / c.max())
