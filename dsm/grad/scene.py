"""The gradient test bed's scene: a ground and one occluder whose vertices follow the parameters.

The meshes are loaded with ``optimize=False`` so Mitsuba keeps them apart (it merges meshes that
share a BSDF otherwise, and the occluder must be found by name). :meth:`GradScene.apply` writes
the occluder's vertex positions as a Dr.Jit expression of the parameters: where a parameter has
gradients enabled, the vertex buffer is attached, and ``scene.ray_intersect`` recomputes each
hit on its triangle with those attached vertices (the map's depths carry the gradient).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import ConfigError
from ..scenes.geometry import box, make_mesh, quad
from . import light as lightmod

GROUND_HALF = 8.0          # the ground's half side, in units of the image window


def occluder_geometry(spec) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of the occluder at the nominal parameters (float64, world)."""
    s, h = spec.occluder_size, spec.occluder_height
    if spec.scene == "plate":
        return quad([0.0, 0.0, h], [s / 2, 0.0, 0.0], [0.0, s / 2, 0.0])
    if spec.scene == "mesh":
        return mesh_geometry(spec.mesh, s, h, spec.source)
    return box([-s / 2, -s / 2, h], [s / 2, s / 2, h + spec.thickness()])


def mesh_geometry(path: str, size: float, height: float, source: str = "<dict>") -> tuple[np.ndarray, np.ndarray]:
    """A PLY or OBJ file's (vertices, faces), scaled so its largest extent is ``size``, centred over the
    origin in x and y, its lowest point at ``height`` (world); ConfigError (key ``gradient.mesh``) for
    a file Mitsuba cannot read, without faces or without extent."""
    kind = "ply" if path.lower().endswith(".ply") else "obj"
    try:
        mesh = mi.load_dict({"type": kind, "filename": path})
    except RuntimeError as e:
        why = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise ConfigError(source, "gradient.mesh", f"{path}: Mitsuba cannot read it ({why})") from None
    p = mi.traverse(mesh)
    v = np.asarray(p["vertex_positions"].numpy(), float).reshape(-1, 3)
    f = np.asarray(p["faces"].numpy(), np.int64).reshape(-1, 3)
    if len(f) == 0 or len(v) == 0 or not np.isfinite(v).all():
        raise ConfigError(source, "gradient.mesh", f"{path}: has no faces or a vertex that is not finite")
    lo, hi = v.min(axis=0), v.max(axis=0)
    if not float(np.max(hi - lo)) > 0.0:
        raise ConfigError(source, "gradient.mesh", f"{path}: has no extent (every vertex at one point)")
    v = (v - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) * (size / float(np.max(hi - lo)))
    return v + np.array([0.0, 0.0, height]), f


class GradScene:
    """The Mitsuba scene of a GradSpec and the occluder's vertex buffer as a function of parameters."""

    def __init__(self, spec):
        self.spec = spec
        self.nominal_light = lightmod.nominal(spec)         # the kit's LightSpec, from the light registry
        half = GROUND_HALF * spec.window
        gv, gf = quad([0.0, 0.0, 0.0], [half, 0.0, 0.0], [0.0, half, 0.0])
        ov, of = occluder_geometry(spec)
        self.ground_np = (gv, np.asarray(gf, np.int64))
        self.occluder_np = (np.asarray(ov, float), np.asarray(of, np.int64))
        self.scene = mi.load_dict({"type": "scene", "ground": make_mesh("ground", gv, gf),
                                   "occluder": make_mesh("occluder", ov, of)}, optimize=False)
        self.params = mi.traverse(self.scene)
        self.names = [s.id() for s in self.scene.shapes()]          # scene.shapes() is not insertion order
        self.base = mi.Float(np.asarray(ov, np.float32).ravel())
        n = len(ov) * 3
        idx = dr.arange(mi.UInt32, n)
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
