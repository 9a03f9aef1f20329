"""The area light's exact soft shadow: per receiver, the fraction of the light's irradiance that arrives.

The light is a square of side ``light_size`` (world) centred on the light's position, facing down
(-z), emitting uniformly (a Lambertian emitter). A ground receiver at o (normal +z) gets from a
light point l the irradiance L cos(theta_o) cos(theta_l) dA / d^2 = L dz^2 / d^4 dA (both cosines
dz / d, d = |l - o|), so its visible fraction is the integral of that kernel over the visible part
of the square over its integral over the whole square: the ratio a renderer's image makes over
the same image without the occluder (:mod:`dsm.grad.projective` divides its renders so).

It is estimated from ``per_axis``^2 stratified light samples per receiver: one seeded random
point in each cell of a per_axis x per_axis grid over the square, one shadow ray each, weighted
by the kernel. The samples are a function of (seed, receiver index) only, so two parameter values
read the same samples (common random numbers): a central difference of the loss then measures
the shadow's change, not the samples' noise.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

LIFT = 1e-4            # a receiver's ray starts this far (in windows) above the ground: far below any gap
SEED = 5               # the light samples' seed of the exact image (the reference draws its own)


def stratum_offsets(rng, per_axis: int, i: int, j: int, count: int) -> tuple:
    """(u, v) in [-0.5, 0.5]: ``count`` seeded random points of stratum (i, j) of the unit square's grid."""
    jitter = rng.uniform(0.0, 1.0, (2, count))
    return (i + jitter[0]) / per_axis - 0.5, (j + jitter[1]) / per_axis - 0.5


def visible_fraction(scene, centre, size: float, p_world, per_axis: int, seed: int, lift: float) -> np.ndarray:
    """The irradiance-weighted visible fraction of the square light (centre: mi.Point3f, side ``size``
    world) at ground points ``p_world`` (mi.Point3f), float64 numpy, from per_axis^2 stratified samples."""
    count = dr.width(p_world)
    o = p_world + mi.Vector3f(0.0, 0.0, lift)
    rng = np.random.default_rng(seed)
    seen, total = np.zeros(count), np.zeros(count)
    for i in range(per_axis):
        for j in range(per_axis):
            u, v = stratum_offsets(rng, per_axis, i, j, count)
            lpos = centre + mi.Vector3f(mi.Float(u.astype(np.float32)) * size, mi.Float(v.astype(np.float32)) * size,
                                        0.0)
            d = lpos - o
            dist = dr.norm(d)
            hit = scene.ray_test(mi.Ray3f(o, d / dist, dist * (1.0 - 1e-6))).numpy()
            dz, dn = d.z.numpy().astype(np.float64), dist.numpy().astype(np.float64)
            w = dz * dz / dn ** 4
            seen += np.where(hit, 0.0, w)
            total += w
    return seen / total
