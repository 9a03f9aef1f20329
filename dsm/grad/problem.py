"""One gradient problem: the scene, the receivers, a loss over the image, and its evaluation.

:meth:`Problem.evaluate` runs the whole technique at parameter values (a dict, in the parameters'
units) with AD on the parameters named in ``wrt``: the occluder's vertices and the light from the
parameters, the view (frame in Dr.Jit), the map (attached intersections), the edge weights for
an antialiased technique, the receivers' projection and the lookup, then the loss and one
backward pass. The image is the ground seen from above: one receiver in each of
``image_resolution``^2 pixels over [-window, window]^2 at z = 0 (at a seeded random point of the
pixel, or its centre), each pixel ``(2 window / N)^2``.

This is the API issue 59's comparisons build on: any image-space loss (a callable of V) and any
parameters of the spec, with the exact image (:meth:`Problem.exact_image`) as a target.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import lights
from ..lights import area_surface
from ..maps.receiver import Receiver
from ..truth import area as truth_area
from ..truth import reference as truth_reference
from . import antialias, build, techniques
from . import light as lightmod
from .occluder import OccluderScene


JITTER_SEED = 7
LIGHT_SEED = 5             # an area light's samples in the exact image (the supersampled reference draws its own)


@dataclass
class Evaluation:
    """A technique's image at some parameter values: the loss, its gradient, the map's classes."""
    loss: float                 # float64 sum over the image of the float32 V
    grads: dict                 # param -> d loss / d param, in the loss's unit per the parameter's unit
    image: np.ndarray           # V per pixel (N, N), row y, column x
    texel_shapes: np.ndarray    # the shape each texel's ray hit (the texels' classes)
    pixel_texels: np.ndarray    # the texel holding each receiver's map position (a nearest lookup's class)
    edge_pairs: int             # texel pairs the antialiasing treated (0 without it)
    edge_structure: np.ndarray  # per texel, which of its pairs the antialiasing treated (all 0 without it)


class Problem:
    """The scene, receivers and loss of a GradSpec, evaluated per technique and parameter values."""

    def __init__(self, spec):
        self.spec = spec
        self.scene = OccluderScene(spec)
        N, W = spec.image_resolution, spec.window
        c = -W + (np.arange(N) + 0.5) * (2.0 * W / N)
        xx, yy = np.meshgrid(c, c)               # row y, column x
        if spec.image_jitter:
            # a regular grid samples the map's reconstruction, whose slope jumps at texel centres, at one
            # phase: a light's parameters move the receivers across that phase and the sum's derivative
            # aliases (+-40 % at a pixel per texel, measured); a seeded jitter turns it into noise that
            # averages over the shadow's edge, and the same points serve every parameter value
            jit = np.random.default_rng(JITTER_SEED).uniform(-0.5, 0.5, (2, N, N)) * (2.0 * W / N)
            xx, yy = xx + jit[0], yy + jit[1]
        self.x_np = xx.ravel().astype(np.float32).astype(np.float64)     # the receivers' x as Dr.Jit holds it
        self.pixel_area = (2.0 * W / N) ** 2
        self.p_world = mi.Point3f(mi.Float(xx.ravel().astype(np.float32)), mi.Float(yy.ravel().astype(np.float32)),
                                  dr.zeros(mi.Float, N * N))
        self.n_world = mi.Vector3f(0.0, 0.0, 1.0)
        self.target = None
        if spec.loss == "l2":
            self.target = self.exact_image({**spec.nominal(), **dict(spec.target)})

    def values(self, overrides: dict | None = None) -> dict:
        """Every parameter's value: the spec's nominal ones with ``overrides``."""
        return {**self.spec.nominal(), **(overrides or {})}

    def _dr_values(self, values: dict, wrt) -> dict:
        out = {}
        for k, v in values.items():
            out[k] = dr.opaque(mi.Float, float(v), 1)        # opaque: one kernel for every value
            if k in wrt:
                dr.enable_grad(out[k])
        return out

    def image_of(self, tech, values: dict, wrt=()):
        """(V per receiver (attached), Dr.Jit parameters, attached map, edge weights) of ``tech``."""
        vals = self._dr_values(values, wrt)
        light = self.scene.apply(vals)
        view = self.scene.view(light)
        amap = build.build(self.scene.scene, view)
        edges = None
        if tech.antialias:
            edges = antialias.edge_weights(amap, self.scene.triangles(vals), light)
        rx = Receiver.make(view, self.p_world, self.n_world, 1.0)
        look = techniques.Lookup(amap, rx, edges, self.spec.bias)
        return techniques.visibility(look, tech), vals, amap, edges, rx

    def loss_of(self, V):
        """The spec's loss of image V (Dr.Jit, attached), for a backward pass over many parameters (its
        float32 atomic sums may differ in the last bits between runs; :meth:`derivative` does not)."""
        kind = self.spec.loss
        if kind == "shadow_area":
            return dr.sum(1.0 - V) * self.pixel_area
        if kind == "shadow_moment_x":
            return dr.sum((1.0 - V) * self.p_world.x) * self.pixel_area
        return dr.mean(dr.square(V - mi.Float(self.target.ravel().astype(np.float32))))

    def loss_np(self, V: np.ndarray) -> float:
        """The same loss of a detached image, summed in float64 (finite differences read this)."""
        v = V.astype(np.float64).ravel()
        if self.spec.loss == "shadow_area":
            return float(np.sum(1.0 - v) * self.pixel_area)
        if self.spec.loss == "shadow_moment_x":
            return float(np.sum((1.0 - v) * self.x_np) * self.pixel_area)
        return float(np.mean(np.square(v - self.target.ravel())))

    def loss_tangent(self, V: np.ndarray, dV: np.ndarray) -> float:
        """d loss from the image ``V`` and its tangent ``dV`` (numpy), summed in float64."""
        v, dv = V.astype(np.float64).ravel(), dV.astype(np.float64).ravel()
        if self.spec.loss == "shadow_area":
            return float(-np.sum(dv) * self.pixel_area)
        if self.spec.loss == "shadow_moment_x":
            return float(-np.sum(dv * self.x_np) * self.pixel_area)
        return float(2.0 * np.sum((v - self.target.ravel()) * dv) / v.size)

    def derivative(self, V, param) -> float:
        """d loss / d ``param`` by forward-mode AD: each pixel's tangent, then an ordered float64 sum.
        (A backward pass accumulates the same sum by float32 atomic adds, whose order, hence last
        bits, differ between identical runs: measured, 0.5985786 to 0.5985788.)"""
        dV = self.tangent(V, param)
        if dV is None:                        # nearest: V does not depend on the parameter at all
            return 0.0
        return self.loss_tangent(dr.detach(V).numpy(), dV) + 0.0       # + 0.0: -0.0 reads as 0

    def tangent(self, V, param):
        """dV / d ``param`` per receiver by forward-mode AD (numpy), None where V does not depend on it."""
        dr.forward(param, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        dV = dr.grad(V)
        return None if dr.width(dV) != dr.width(V) else dV.numpy()

    def evaluate(self, tech, values: dict, wrt=()) -> Evaluation:
        """The loss of ``tech`` at ``values`` and, for each parameter in ``wrt``, its AD derivative
        (forward mode, one pass per parameter: the same answer on every run)."""
        V, vals, amap, edges, rx = self.image_of(tech, values, tuple(wrt)[:1])
        grads = {}
        for n, k in enumerate(wrt):
            Vk, valsk = (V, vals) if n == 0 else self.image_of(tech, values, (k,))[:2]
            grads[k] = self.derivative(Vk, valsk[k])
        N = self.spec.image_resolution
        image = dr.detach(V).numpy().reshape(N, N)
        u, v = dr.detach(rx.u_map), dr.detach(rx.v_map)
        return Evaluation(self.loss_np(image), grads, image, amap.smap.shape.numpy(), self._texel(u, v),
                          edges.pairs if edges is not None else 0,
                          edges.structure if edges is not None else np.zeros(1, np.uint8))

    def _texel(self, u, v) -> np.ndarray:
        """The texel index holding map positions (u, v) (clamped to the map), numpy."""
        R = self.spec.map_resolution
        return (dr.clip(mi.Int32(dr.floor(v)), -1, R) * (R + 2) + dr.clip(mi.Int32(dr.floor(u)), -1, R)).numpy()

    def exact_image(self, values: dict) -> np.ndarray:
        """The exact (ray-traced) visibility per pixel at ``values``: one shadow ray per receiver."""
        N = self.spec.image_resolution
        return self.exact_at(values, self.p_world).reshape(N, N)

    def exact_at(self, values: dict, p_world, light_seed: int = LIGHT_SEED) -> np.ndarray:
        """The exact visibility (numpy) at ground points ``p_world`` (mi.Point3f) at ``values``, the kit's:
        one shadow ray per receiver (dsm.truth.reference) under a hard light, 0 or 1; under an area light
        the irradiance-weighted visible fraction (dsm.truth.area.irradiance_fraction), its samples keyed by
        ``light_seed``."""
        self.scene.apply(self._dr_values(values, ()))
        light = lightmod.floats(self.scene.nominal_light, values)
        si = self.scene.ground_interactions(p_world)
        scene, magnitude = self.scene.scene, self.scene.magnitude
        if lights.is_soft(light):
            return truth_area.irradiance_fraction(scene, si, si.n, area_surface.geometry(light),
                                                  self.spec.light_samples, light_seed, magnitude)
        visible, _ = truth_reference.visibility(scene, si, light, magnitude)
        return np.where(visible.numpy(), 1.0, 0.0)
