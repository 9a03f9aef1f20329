"""dsm grad's scene: the kit's occluder built-in, its occluder's vertices following the parameters.

The scene is the config's ``[[scene]]`` table (GradSpec's scene fields, :mod:`.kit_tables`: the
built-ins ``occluder_plate``, ``occluder_box``, ``occluder_mesh`` of :mod:`dsm.scenes.params`),
read again by the kit's parser (:func:`dsm.scenes.spec.parse_scene`: its checks, a mesh file through the
kit's mesh loading) and built from the built-in's geometry (shapes ``ground`` and ``occluder``), so a
``dsm run`` of the same table sees the same triangles. The meshes are loaded with ``optimize=False``
so Mitsuba keeps them apart (it merges meshes that share a BSDF otherwise, and the occluder must be
found by name).

What is grad's own: :meth:`OccluderScene.apply` writes the occluder's vertex positions as a Dr.Jit
expression of the parameters; where a parameter has gradients enabled, the vertex buffer is attached,
and ``scene.ray_intersect`` recomputes each hit on its triangle with those attached vertices (the
map's depths carry the gradient).
"""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..scenes.builtins import builtin_geometry
from ..scenes.geometry import make_mesh
from ..scenes.spec import parse_scene
from . import light as lightmod
from .kit_tables import SCENES

GROUND_HALF = 8.0          # the ground's half side, in units of the image window
# GradSpec.scene -> the kit's built-in (kit_tables.SCENES turned round: the names live there alone)
BUILTINS = {scene: builtin for builtin, scene in SCENES.items()}


def scene_table(spec) -> dict:
    """The ``[[scene]]`` table (world units) of the spec's scene at its nominal values."""
    t = {"builtin": BUILTINS[spec.scene], "size": spec.occluder_size, "height": spec.occluder_height,
         "ground_half": GROUND_HALF * spec.window}
    if spec.scene == "box":
        t["box_height"] = spec.thickness()
    if spec.scene == "mesh":
        t["mesh"] = spec.mesh
    return t


def shapes(spec) -> dict:
    """The built-in's shapes {"ground", "occluder": (vertices float64, faces)} at the nominal values, read
    by the kit's [[scene]] parser (a mesh Mitsuba cannot read: ``scene[0].mesh``, the table's own key)."""
    (scene,) = parse_scene(scene_table(spec), spec.source, "scene[0]", Path(spec.source).parent)
    return builtin_geometry(scene.builtin, scene.params)[0]


class OccluderScene:
    """The Mitsuba scene of a GradSpec and the occluder's vertex buffer as a function of parameters."""

    def __init__(self, spec):
        self.spec = spec
        self.nominal_light = lightmod.nominal(spec)         # the kit's LightSpec, from the light registry
        geometry = {n: (np.asarray(v, float), np.asarray(f, np.int64)) for n, (v, f) in shapes(spec).items()}
        self.ground_np, self.occluder_np = geometry["ground"], geometry["occluder"]
        self.scene = mi.load_dict({"type": "scene", **{n: make_mesh(n, v, f) for n, (v, f) in geometry.items()}},
                                  optimize=False)
        self.params = mi.traverse(self.scene)
        self.names = [s.id() for s in self.scene.shapes()]          # scene.shapes() is not insertion order
        ov = self.occluder_np[0]
        self.base = mi.Float(np.asarray(ov, np.float32).ravel())
        idx = dr.arange(mi.UInt32, len(ov) * 3)
        self._is_z, self._is_x, self._corner_z = (idx % 3 == 2), (idx % 3 == 0), (idx == 2)

    def vertex_positions(self, values: dict):
        """The occluder's vertex buffer (flat mi.Float, world) at parameter ``values`` (Dr.Jit scalars)."""
        pos = self.base + dr.select(self._is_z, values["occluder_z"], 0.0)
        pos = pos + dr.select(self._is_x, values["occluder_x"], 0.0)
        return pos + dr.select(self._corner_z, values["corner_z"], 0.0)

    def apply(self, values: dict):
        """Move the occluder to parameter ``values`` (rebuilding the scene) and return the light there (the
        kit's LightSpec, its position or direction attached: dsm.grad.light.at)."""
        self.params["occluder.vertex_positions"] = self.vertex_positions(values)
        self.params.update()
        return lightmod.at(self.nominal_light, values)

    def view(self, light):
        """The map's view of ``light`` (attached), its depth range up to the occluder's nominal top."""
        return lightmod.map_view(self.spec, light, float(np.max(self.occluder_np[0][:, 2])))

    @property
    def magnitude(self) -> float:
        """The scene's largest absolute coordinate (the spawn offsets' extent for shapes that are not meshes)."""
        return float(GROUND_HALF * self.spec.window)

    def ground_interactions(self, p_world):
        """Surface interactions on the ground at points ``p_world`` (on z = 0; normal +z), as the kit's
        exact side reads a receiver (dsm.truth: the spawn offset from the ground's triangle)."""
        n = dr.width(p_world)
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.p = mi.Point3f(p_world)
        si.n = dr.zeros(mi.Normal3f, n) + mi.Normal3f(0.0, 0.0, 1.0)
        si.shape = mi.ShapePtr(self.scene.shapes()[self.shape_index("ground")])
        return si

    def shape_index(self, name: str) -> int:
        """The index into ``scene.shapes()`` of shape ``name``."""
        return self.names.index(name)

    def triangles(self, values: dict):
        """Per shape index of ``scene.shapes()``: (flat vertex buffer as Dr.Jit sees it, faces (numpy)).
        The occluder's buffer is the attached expression of ``values``; the ground's is fixed."""
        out = [None] * len(self.names)
        out[self.shape_index("occluder")] = (self.vertex_positions(values), self.occluder_np[1])
        out[self.shape_index("ground")] = (mi.Float(np.asarray(self.ground_np[0], np.float32).ravel()),
                                           self.ground_np[1])
        return out
