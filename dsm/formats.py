"""Stored depth formats: the precision of the depth buffer (seed 002, "depth-buffer precision").

A format other than ``float32`` quantizes the stored layers (z1, z2) once per map, and the
lookup compares against the stored value converted back, as hardware converts a stored
depth before its comparison:

- ``unorm16`` / ``unorm24``: the depth's position in the view's [near, far] range, rounded
  to 2^16 - 1 / 2^24 - 1 steps: a constant world step (far - near) / (2^b - 1).
- ``ndc24``: a perspective projection's depth ``f / (f - n) * (1 - n / z)`` (D3D's [0, 1]
  convention) in 24 bits. Its world step grows as z^2 (f - n) / (f n 2^24): fine near the
  light, coarse far from it. Orthographic views have linear NDC depth (= unorm24). ``n`` is
  the distance from the light to the scene's bounds, at least 1/1000 of far.

Quantization runs in float64 (numpy) so that the only error is the format's own. Texels
where the ray hit nothing keep the far bound.
"""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

FORMATS = ("float32", "unorm16", "unorm24", "ndc24")
BITS = {"unorm16": 16, "unorm24": 24, "ndc24": 24}


def ndc_near(view) -> float:
    return max(float(getattr(view, "nearest_scene_depth", 0.0)), view.far * 1e-3)


def quantize_np(z: np.ndarray, view, fmt: str) -> np.ndarray:
    """World depths ``z`` as stored in ``fmt`` and read back (float64 math)."""
    if fmt == "float32":
        return z
    z = np.asarray(z, np.float64)
    steps = float(2 ** BITS[fmt] - 1)
    near, far = float(view.near), float(view.far)
    if fmt == "ndc24" and view.kind != "orthographic":
        n = ndc_near(view)
        zc = np.clip(z, n, far)
        ndc = far / (far - n) * (1.0 - n / zc)
        q = np.round(np.clip(ndc, 0.0, 1.0) * steps) / steps
        return n / (1.0 - q * (far - n) / far)
    t = np.clip((z - near) / (far - near), 0.0, 1.0)
    return near + np.round(t * steps) / steps * (far - near)


def world_step(view, fmt: str, z):
    """The world-space size of one stored step at depth ``z`` (numpy)."""
    steps = float(2 ** BITS[fmt] - 1)
    z = np.asarray(z, np.float64)
    if fmt == "ndc24" and view.kind != "orthographic":
        n, f = ndc_near(view), view.far
        return z * z * (f - n) / (f * n) / steps
    return np.full_like(z, (view.far - view.near) / steps)


def store(smap, fmt: str):
    """A copy of the map with its depth layers in ``fmt`` (the same map for float32)."""
    if fmt == "float32":
        return smap
    out = {}
    for name in ("z1", "z2"):
        z = getattr(smap, name)
        if z is None:
            continue
        zn = z.numpy().astype(np.float64)
        keep = zn >= smap.view.far          # misses stay at the far bound
        q = quantize_np(zn, smap.view, fmt)
        out[name] = mi.Float(np.where(keep, zn, q).astype(np.float32))
    return dataclasses.replace(smap, **out)
