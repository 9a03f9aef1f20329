"""The primary truth of a gradient: central differences of the exact image, supersampled.

Each pixel of the image holds ``S``^2 receivers, one at a seeded random point of each cell of an
S x S grid over the pixel (stratified), each with one shadow ray (:meth:`Problem.exact_at`); a
pixel's exact V is their mean. The loss of that image is a step function of the parameters at
each receiver, so its central difference (L(p + s) - L(p - s)) / 2s counts the receivers the
shadow's edge sweeps within +-s: a slope where many are swept, with a second-order bias
(s^2 L''' / 6) that a smaller step trades for noise. The estimate's own error is read from the
two: the same difference at step s / 2, and at step s over a second seed of the receivers; the
reported error is the larger change. The per-pixel image of the difference is the reference of
a technique's per-pixel tangent (cosine similarity).

Under an area light a receiver's exact V is the irradiance-weighted visible fraction of the light
(:func:`dsm.truth.area.irradiance_fraction`), from stratified light samples keyed by the receiver and seed: the same samples at p + s and p - s (common
random numbers), and a second seed draws both new receivers and new light samples.

Each difference also keeps its per-pixel loss image (the pixel's receivers' part of the loss's
difference), so the reference restricted to some pixels (:meth:`Reference.masked`: those a
camera sees, :mod:`.projective`) is a sum over them, with its own error the same way.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

SEEDS = (11, 12)


@dataclass
class Reference:
    """d loss / d param from the supersampled exact image, its error estimate and per-pixel image."""
    param: str
    value: float                 # (L(p + s) - L(p - s)) / 2s, seed SEEDS[0]
    step: float                  # s, in the parameter's unit
    samples: int                 # receivers per pixel (S^2)
    at_half_step: float          # the same at s / 2
    other_seed: float            # the same at s over SEEDS[1]'s receivers
    image: np.ndarray            # (N, N): d V_pixel / d param (the pixel's mean over its receivers)
    loss_images: tuple = ()      # (N, N) x 3: each pixel's part of value, at_half_step, other_seed

    @property
    def error(self) -> float:
        """The estimate's own error: the larger change under halving the step or changing the seed."""
        return max(abs(self.value - self.at_half_step), abs(self.value - self.other_seed))

    def masked(self, pixels: np.ndarray) -> "Reference":
        """The reference of the loss over the (N, N) bool ``pixels`` only (its error estimated the same way)."""
        value, half, other = (float(np.sum(img[pixels])) + 0.0 for img in self.loss_images)
        return Reference(self.param, value, self.step, self.samples, half, other,
                         np.where(pixels, self.image, 0.0), tuple(np.where(pixels, i, 0.0) for i in self.loss_images))


class Supersampled:
    """The exact image of a Problem with ``per_axis``^2 stratified receivers per pixel (one seed)."""

    def __init__(self, problem, per_axis: int, seed: int):
        spec = problem.spec
        N, S, W = spec.image_resolution, per_axis, spec.window
        cell = 2.0 * W / (N * S)
        rng = np.random.default_rng(seed)
        c = -W + (np.arange(N * S) + 0.5) * cell
        xx, yy = np.meshgrid(c, c)
        xx = xx + rng.uniform(-0.5, 0.5, xx.shape) * cell
        yy = yy + rng.uniform(-0.5, 0.5, yy.shape) * cell
        self.problem, self.N, self.S, self.seed = problem, N, S, seed
        self.x = xx.astype(np.float32).astype(np.float64)          # as Dr.Jit holds them
        self.p_world = mi.Point3f(mi.Float(xx.ravel().astype(np.float32)),
                                  mi.Float(yy.ravel().astype(np.float32)), dr.zeros(mi.Float, xx.size))
        self.weight = (2.0 * W / (N * S)) ** 2                      # world^2 per receiver

    def visibility(self, values: dict) -> np.ndarray:
        """Exact V per receiver, (N S, N S), row y."""
        n = self.N * self.S
        return self.problem.exact_at(values, self.p_world, light_seed=self.seed).reshape(n, n)

    def loss(self, v: np.ndarray) -> float:
        """The spec's loss (shadow_area or shadow_moment_x) of receiver visibilities ``v``, float64."""
        kind = self.problem.spec.loss
        if kind == "shadow_area":
            return float(np.sum(1.0 - v) * self.weight)
        if kind == "shadow_moment_x":
            return float(np.sum((1.0 - v) * self.x) * self.weight)
        raise ValueError(f"the supersampled reference has no {kind!r} loss (shadow_area, shadow_moment_x)")

    def loss_pixels(self, v: np.ndarray) -> np.ndarray:
        """Each pixel's part of the loss (N, N): its receivers' terms summed, float64."""
        kind = self.problem.spec.loss
        terms = (1.0 - v) * self.weight if kind == "shadow_area" else (1.0 - v) * self.x * self.weight
        return terms.reshape(self.N, self.S, self.N, self.S).sum(axis=(1, 3))

    def pixels(self, v: np.ndarray) -> np.ndarray:
        """Per-pixel mean of receiver visibilities (N, N)."""
        return v.reshape(self.N, self.S, self.N, self.S).mean(axis=(1, 3))

    def difference(self, param: str, step: float, values: dict) -> tuple:
        """(central difference of the loss, per-pixel difference image, per-pixel loss difference) in
        ``param`` at ``values``."""
        lo, hi = dict(values), dict(values)
        lo[param] -= step
        hi[param] += step
        v_lo, v_hi = self.visibility(lo), self.visibility(hi)
        d = (self.loss(v_hi) - self.loss(v_lo)) / (2.0 * step)
        parts = (self.loss_pixels(v_hi) - self.loss_pixels(v_lo)) / (2.0 * step)
        return d, (self.pixels(v_hi) - self.pixels(v_lo)) / (2.0 * step), parts


def reference(problem, param: str, per_axis: int, step: float, values: dict | None = None) -> Reference:
    """The supersampled central difference of ``problem``'s loss in ``param``, with its error estimate."""
    values = problem.values(values)
    first = Supersampled(problem, per_axis, SEEDS[0])
    value, image, parts = first.difference(param, step, values)
    half, _, parts_half = first.difference(param, step / 2.0, values)
    other, _, parts_other = Supersampled(problem, per_axis, SEEDS[1]).difference(param, step, values)
    return Reference(param, value + 0.0, step, per_axis ** 2, half + 0.0, other + 0.0, image,
                     (parts, parts_half, parts_other))
