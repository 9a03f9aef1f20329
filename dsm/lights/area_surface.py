"""An area light's surface (dsm.truth.area samples it): its shape in the world, the map from the
unit square to it (area preserving), which receivers see part of it, and the map's view from
its centre. Shapes and keys: :mod:`dsm.lights.area`."""
from __future__ import annotations

import math
from dataclasses import dataclass

import mitsuba as mi
import numpy as np
import drjit as dr

from ..core.types import AREA_SHAPES as SHAPES
from ..maps.views import CubeView, ParaboloidView, PerspectiveView, light_frame
from ..scenes.emitters import mesh_triangles
from ..core.suggest import unknown

PERSPECTIVE_MAX_DEG = 70.0     # beyond this half angle a one-sided light's map is a paraboloid


def unit(v) -> np.ndarray:
    """``v`` scaled to length 1 (float64)."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@dataclass
class Geometry:
    """An area light's surface: the map from the unit square to it (area preserving) and the
    test of which receivers see part of it."""
    shape: str
    centre: np.ndarray
    normal: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    extent: tuple                 # rectangle (w, h); disk, sphere (radius,)
    tris: np.ndarray | None = None    # emitter triangles (n, 3, 3), world, float64
    dist: object = None           # mi.DiscreteDistribution over the triangles' areas
    exclude: tuple = ()

    @property
    def one_sided(self) -> bool:
        """Whether the light lights one side only (every shape but the sphere)."""
        return self.shape != "sphere"

    @property
    def area(self) -> float:
        """The light's surface area in world units squared (an emitter's: its triangles' summed areas)."""
        if self.shape == "rectangle":
            return self.extent[0] * self.extent[1]
        if self.shape == "disk":
            return math.pi * self.extent[0] ** 2
        if self.shape == "sphere":
            return 4 * math.pi * self.extent[0] ** 2
        return float(0.5 * np.linalg.norm(np.cross(self.tris[:, 1] - self.tris[:, 0],
                                                   self.tris[:, 2] - self.tris[:, 0]), axis=1).sum())

    def sample(self, u, v, p):
        """(points, light normals) of square samples (u, v) for receivers at ``p`` (Dr.Jit)."""
        c = mi.Point3f(*map(float, self.centre))
        nrm = mi.Vector3f(*map(float, self.normal))
        ex, ey = mi.Vector3f(*map(float, self.ex)), mi.Vector3f(*map(float, self.ey))
        n = dr.width(u)
        if self.shape == "rectangle":
            w, h = self.extent
            x = c + ex * ((u - 0.5) * w) + ey * ((v - 0.5) * h)
            return x, dr.zeros(mi.Vector3f, n) + nrm
        if self.shape == "disk":
            d = mi.warp.square_to_uniform_disk_concentric(mi.Point2f(u, v)) * self.extent[0]
            return c + ex * d.x + ey * d.y, dr.zeros(mi.Vector3f, n) + nrm
        if self.shape == "sphere":
            r = self.extent[0]
            to_rx = p - c
            dist = dr.norm(to_rx)
            cos_cap = dr.minimum(r / dr.maximum(dist, r), 1.0)
            local = mi.warp.square_to_uniform_cone(mi.Point2f(u, v), cos_cap)
            w = mi.Frame3f(to_rx / dist).to_world(local)
            return c + w * r, w
        idx, u2 = self.dist.sample_reuse(u)
        t = self.tris
        b = mi.warp.square_to_uniform_triangle(mi.Point2f(u2, v))
        corner = [mi.Point3f(*(mi.Float(np.asarray(t[:, k, a], np.float32)) for a in range(3))) for k in range(3)]
        pk = [dr.gather(mi.Point3f, ck, idx) for ck in corner]
        x = pk[0] * (1.0 - b.x - b.y) + pk[1] * b.x + pk[2] * b.y
        return x, dr.normalize(dr.cross(pk[1] - pk[0], pk[2] - pk[0]))

    def receivers(self, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """Whether part of the light is above each receiver's tangent plane (and, for a one-sided
        light, the receiver is in front of it): (m, 3) positions and normals, float64."""
        if self.shape == "rectangle":
            w, h = self.extent
            pts = np.array([self.centre + self.ex * a * w / 2 + self.ey * b * h / 2
                            for a in (-1, 1) for b in (-1, 1)])
            above = ((pts[None] - p[:, None]) * n[:, None]).sum(-1).max(1) > 0
        elif self.shape == "disk":
            r = self.extent[0]
            nn = n - np.outer(n @ self.normal, self.normal)
            above = ((self.centre - p) * n).sum(1) + r * np.linalg.norm(nn, axis=1) > 0
        elif self.shape == "sphere":
            return ((self.centre - p) * n).sum(1) + self.extent[0] > 0
        else:
            verts = self.tris.reshape(-1, 3)
            above = np.zeros(len(p), bool)
            for k in range(0, len(verts), 64):
                above |= ((verts[None, k:k + 64] - p[:, None]) * n[:, None]).sum(-1).max(1) > 0
            # in front of some triangle's emitting side
            tn = np.cross(self.tris[:, 1] - self.tris[:, 0], self.tris[:, 2] - self.tris[:, 0])
            front = np.zeros(len(p), bool)
            for k in range(0, len(tn), 64):
                front |= (((p[:, None] - self.tris[None, k:k + 64, 0]) * tn[None, k:k + 64]).sum(-1) > 0).any(1)
            return above & front
        return above & (((p - self.centre) @ self.normal) > 0)


def geometry(light, scene=None) -> Geometry:
    """The surface of an area LightSpec (``scene``: for emitter lights, their triangles)."""
    c = np.asarray(light.position, float)
    nrm = unit(light.direction if light.direction is not None else (0.0, 0.0, -1.0))
    ex, ey, _ = light_frame(nrm)
    if light.shape == "rectangle":
        w, h = (light.size * 2)[:2] if len(light.size) == 1 else light.size[:2]
        return Geometry("rectangle", c, nrm, ex, ey, (float(w), float(h)))
    if light.shape in ("disk", "sphere"):
        return Geometry(light.shape, c, nrm, ex, ey, (0.5 * float(light.size[0]),))
    if light.shape == "emitter":
        shapes = list(scene.shapes())
        tris = np.concatenate([mesh_triangles(shapes[i]) for i in light.emitter_shapes])
        area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
        return Geometry("emitter", c, nrm, ex, ey, (), tris, mi.DiscreteDistribution(area.astype(np.float32)),
                        tuple(light.emitter_shapes))
    raise ValueError(unknown("area light shape", light.shape, SHAPES))


def light_size(light) -> float:
    """The light's width in world units (PCSS's light size): the side of a square light, the
    larger side of a rectangle, a disk's or sphere's diameter, an emitter's square root of area."""
    return float(max(light.size)) if light.size else 0.0


def make_view(light, R, receivers_world, bbox, kind=None):
    """The map of an area light, cast from its centre: for a one-sided light a perspective view
    along its normal whose field of view is fitted to the receivers (``kind`` "fitted"), or a
    paraboloid around the normal when they span more than PERSPECTIVE_MAX_DEG; for a sphere the
    point-light view ``kind``. The view carries ``light_size`` (for PCSS), ``light_surface`` (SMRT's
    ray targets; an emitter light's is given by the runner, which has the scene) and ``exclude`` (the luminaire's own shapes, which its map
    steps over)."""
    c = np.asarray(light.position, float)
    nrm = unit(light.direction if light.direction is not None else (0.0, 0.0, -1.0))
    if light.shape == "sphere":
        if kind == "cube":
            view = CubeView(c, bbox, R)
        elif kind in ("paraboloid", "dual_paraboloid"):
            view = ParaboloidView(c, nrm, bbox, R, dual=kind == "dual_paraboloid")
        else:
            raise ValueError(unknown("sphere-light view", kind, ("paraboloid", "dual_paraboloid", "cube")))
    else:
        pts = np.asarray(receivers_world, float).reshape(-1, 3) - c
        dist = np.linalg.norm(pts, axis=1)
        ok = dist > 0
        cosang = (pts[ok] @ nrm) / dist[ok] if ok.any() else np.ones(1)
        theta = float(np.degrees(np.arccos(np.clip(cosang.min(), -1.0, 1.0))))
        if theta <= PERSPECTIVE_MAX_DEG:
            # the square map's half angle covers the receivers' cone with a little to spare
            view = PerspectiveView(c, nrm, min(max(theta * 1.02 + 0.5, 1.0), PERSPECTIVE_MAX_DEG + 1.0), bbox, R)
        else:
            view = ParaboloidView(c, nrm, bbox, R, dual=False)
    view.light_size = light_size(light)
    # SMRT's rays aim at points of the surface; an emitter's triangles are the scene's, not at hand here
    # (the runner gives its view the emitter's surface: dsm.experiment.runner)
    view.light_surface = None if light.shape == "emitter" else geometry(light)
    view.exclude = tuple(light.emitter_shapes)
    return view
