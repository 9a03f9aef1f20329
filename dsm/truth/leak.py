"""Light leaking as the pre-filtering papers mean it (Donnelly & Lauritzen 2006; Lauritzen & McCool
2008; Peters & Klein 2015): false light *inside* an exact shadow, where the filtered statistics, not
the map's resolution, let the light through.

A receiver is **deep in shadow** when it lies at least ``k`` texels (at the receiver) inside the
exact shadow: no probe of a fixed, seedless pattern around it is exactly lit. The pattern:
PROBE_ANGLES directions, evenly spaced on its tangent plane, at PROBE_RADII times ``k`` texels.
Each probe point is moved onto the receiver's own surface by a ray along the normal (from as far
above the plane as the probe is from the receiver, back down to as far below) and traced from
there toward the light as the reference traces a receiver; a probe whose ray finds another shape
or none (past the edge of its surface: the edge of a plate whose shadow's outline lies beyond it)
is traced from its point on the tangent plane. A peter-panned receiver (V* = 0, the map lights it)
that is deep in shadow leaks; one within ``k`` texels of an exactly lit point is at the shadow's
edge, which a depth map's resolution and bias decide, never leak. The probes find a lit point
between them only up to the pattern's spacing (its outer ring's chord, 0.77 k texels): a lit
sliver narrower than that, between two probes, is missed.
"""
from __future__ import annotations

import numpy as np

from .. import lights
from ..scenes import spawn
from . import reference

PROBE_ANGLES = 8
PROBE_RADII = (0.5, 1.0)          # of k texels


def probe_offsets() -> np.ndarray:
    """(probes, 2): each probe's (along t1, along t2) in units of k texels."""
    a = 2.0 * np.pi * np.arange(PROBE_ANGLES) / PROBE_ANGLES
    return np.concatenate([np.stack([r * np.cos(a), r * np.sin(a)], axis=1) for r in PROBE_RADII])


def tangent_basis(normal: np.ndarray) -> tuple:
    """(t1, t2), unit and orthogonal to each (n, 3) normal and to each other."""
    n = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def deep_in_shadow(scene, p: np.ndarray, normal: np.ndarray, shape: np.ndarray, texel_world: np.ndarray,
                   k_texels: float, light, magnitude: float) -> np.ndarray:
    """Per receiver (positions ``p`` and normals ``normal``, (n, 3) in ``scene``'s frame; ``shape``:
    its shape index; ``texel_world``: a texel's size there): whether it lies at least ``k_texels``
    texels inside the exact shadow of ``light`` on its own surface (the module's probes)."""
    n = len(p)
    if n == 0:
        return np.zeros(0, bool)
    offs = probe_offsets()
    t1, t2 = tangent_basis(normal)
    unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    radius = k_texels * np.asarray(texel_world, np.float64)                 # (n,)
    # probe j of receiver i at row j * n + i
    q = np.concatenate([p + radius[:, None] * (a * t1 + b * t2) for a, b in offs])
    lift = np.tile(np.maximum(radius, 1e-30) * np.max(np.hypot(offs[:, 0], offs[:, 1])), len(offs))
    up = np.tile(unit, (len(offs), 1))
    o = q + up * lift[:, None]
    ray = spawn.rays_np(o, -up, 2.0 * lift)
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    valid = pi.is_valid()
    # Shape identity, not the acne split's surface test (issue 78): the probe's ray spans only
    # +-lift (k texels) about the tangent plane, so a hit on another surface of the receiver's own
    # mesh lies within k texels of the receiver (a contact), and a lit point there marks the
    # shadow's edge all the same; between separate shapes it tells a plate's edge as before.
    own = np.asarray(spawn.hit_shape(pi, valid, spawn.shape_table(scene)).numpy(), np.int64) == np.tile(shape, len(offs))
    si = pi.compute_surface_interaction(ray)
    on_surface, _ = reference.visibility(scene, si, light, magnitude)
    lit = own & on_surface.numpy().astype(bool)
    off = np.flatnonzero(~own)              # past the surface's edge: traced from the plane, only those
    if len(off):
        lit[off] = point_visibility(scene, q[off] + up[off] * (1e-3 * lift[off, None]), light)
    return ~lit.reshape(len(offs), n).any(axis=0)


def point_visibility(scene, q: np.ndarray, light) -> np.ndarray:
    """Whether each point ``q`` ((m, 3), in the air, no surface of its own) sees ``light`` (bool)."""
    if lights.get(light.type).POSITIONAL:
        to = np.asarray(light.position, np.float64)[None, :] - q
        dist = np.linalg.norm(to, axis=1)
        d, maxt = to / np.maximum(dist, 1e-30)[:, None], dist * (1.0 - 1e-6)
    else:
        d = np.broadcast_to(-np.asarray(light.direction, np.float64) / np.linalg.norm(light.direction), q.shape)
        maxt = np.full(len(q), np.inf)
    return ~scene.ray_test(spawn.rays_np(q, d, maxt), coherent=False).numpy().astype(bool)
