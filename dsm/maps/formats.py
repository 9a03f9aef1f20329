"""Stored depth formats: the precision of the depth buffer (Microsoft's Common Techniques article, "depth-buffer precision").

A format other than ``float32`` quantizes the stored layers (z1, z2) once per map, and the
lookup compares against the stored value converted back, as hardware converts a stored
depth before its comparison:

- ``unorm16`` / ``unorm24``: the depth's position in the view's [near, far] range, rounded
  to 2^16 - 1 / 2^24 - 1 steps: a constant world step (far - near) / (2^b - 1).
- ``ndc24``: a perspective projection's depth ``f / (f - n) * (1 - n / z)`` (D3D's [0, 1]
  convention) in 24 bits, of the depth the hardware projects: ``z`` is the distance along
  the spot's axis, and on a cube face the distance along that face's axis (not the
  Euclidean distance, which a rasterizer cannot store): a cube map in ndc24 therefore uses
  the face-axis depth for every layer and every receiver (:class:`AxisDepthCube`), so the
  comparison happens in the quantity stored. Its world step grows as z^2 (f - n) / (f n 2^24):
  fine near the light, coarse far from it.
- ``float16``: the depth's position in [near, far] as an IEEE half (a 16-bit float render
  target, as pre-filtered moment maps use; :mod:`dsm.prefilter` stores its moments so): 11
  significant bits, so a relative step of 2^-11 of the normalized depth, fine near ``near``. Orthographic views have linear NDC depth (=
  unorm24); paraboloid maps store the Euclidean distance linearly between near and far
  (Brabec, Annen & Seidel 2002), so ndc24 there equals unorm24. ``n`` is the distance from
  the light to the scene's bounds, at least 1/1000 of far.

The stored value is decoded (in float64) back to the view's depth, and the scheme compares
there; decoding is monotonic, so this equals the comparison in the stored representation
up to float32 rounding of the decoded value. Dou et al.'s adaptive epsilon (Dou et al. 2014,
eq. 2: f'(x) dx in stored units) is dx in these decoded units.

Quantization runs in float64 (numpy) so that the only error is the format's own. Texels
where the ray hit nothing keep the far bound.
"""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

from ..core.types import FORMATS

BITS = {"unorm16": 16, "unorm24": 24, "ndc24": 24}


NDC_KINDS = ("perspective", "cube")    # views whose ndc24 depth is projective (the others: linear)


class AxisDepthCube:
    """A cube view whose depth is the distance along each face's axis (what ndc24 stores)."""

    def __init__(self, cube):
        self._cube = cube

    def __getattr__(self, name):
        return getattr(self._cube, name)

    def depth(self, p):
        """Depth of world points ``p``: the distance along their cube face's axis."""
        face = self._cube.face_of(p)
        _, _, W = self._cube.face_axes(face)
        return dr.dot(p - self._cube.o, W)

    def plane_hit(self, u, v, p0, n, face=None):
        """(depth, met) as View.plane_hit gives them, in the face-axis depth."""
        depth, met = type(self._cube).plane_hit(self, u, v, p0, n, face)
        return depth, met

    def depth_on_plane(self, u, v, p0, n, face=None):
        """Face-axis depth where the ray through (u, v) of ``face`` meets the plane (p0, n); +inf where it does not."""
        return self.plane_hit(u, v, p0, n, face)[0]


def stored_view(view, fmt: str):
    """The view whose depth function a format stores (the view itself but for ndc24 cubes)."""
    return AxisDepthCube(view) if fmt == "ndc24" and view.kind == "cube" else view


def _texel_axis_cosine(view) -> np.ndarray:
    """Per texel of a cube map: the cosine between the texel centre's ray and its face's axis."""
    if view.virtual:        # faces that differ in resolution, through pages: each stored texel's own ray
        face, cu, cv = view.texel_coords(dr.arange(mi.UInt32, view.n_texels))
        _, d = view.ray_at(cu, cv, face)
        return np.asarray(dr.dot(d, view.face_axes(face)[2]).numpy(), np.float64)
    R = view.resolution
    c = (np.arange(R) + 0.5) / R * 2.0 - 1.0
    a, b = np.meshgrid(c, c)                     # row j (v), column i (u)
    cos = 1.0 / np.sqrt(1.0 + a * a + b * b)
    return np.tile(cos.ravel(), view.faces)


def ndc_near(view) -> float:
    """ndc24's near distance ``n``: the light's distance to the scene's bounds, at least far / 1000."""
    return max(float(view.nearest_scene_depth), view.far * 1e-3)


def quantize_np(z: np.ndarray, view, fmt: str, bounds=None) -> np.ndarray:
    """World depths ``z`` as stored in ``fmt`` and read back (float64 math); ``bounds``: (near,
    far) per value (a cascaded map's View.texel_bounds), None: the view's."""
    if fmt == "float32":
        return z
    z = np.asarray(z, np.float64)
    near, far = (float(view.near), float(view.far)) if bounds is None else bounds
    if fmt == "float16":
        t = np.clip((z - near) / (far - near), 0.0, 1.0)
        return near + t.astype(np.float16).astype(np.float64) * (far - near)
    steps = float(2 ** BITS[fmt] - 1)
    if fmt == "ndc24" and view.kind in NDC_KINDS:
        n = ndc_near(view)
        zc = np.clip(z, n, far)
        ndc = far / (far - n) * (1.0 - n / zc)
        q = np.round(np.clip(ndc, 0.0, 1.0) * steps) / steps
        return n / (1.0 - q * (far - n) / far)
    t = np.clip((z - near) / (far - near), 0.0, 1.0)
    return near + np.round(t * steps) / steps * (far - near)


def store(smap, fmt: str):
    """A copy of the map with its depth layers in ``fmt`` (the same map for float32)."""
    if fmt == "float32":
        return smap
    view = stored_view(smap.view, fmt)
    # the hit's depth along its face's axis: the Euclidean distance times the texel ray's cosine
    cos = _texel_axis_cosine(smap.view) if view is not smap.view else None
    out = {"view": view}
    for name in ("z1", "z2"):
        z = getattr(smap, name)
        if z is None:
            continue
        zn = z.numpy().astype(np.float64)
        keep = zn >= smap.view.far          # misses stay at the far bound
        za = zn * cos if cos is not None else zn
        # a cascaded map: each cascade's own near and far
        bounds = smap.view.texel_bounds() if za.shape == (smap.view.n_texels,) else None
        q = quantize_np(za, smap.view, fmt, bounds)
        out[name] = mi.Float(np.where(keep, zn, q).astype(np.float32))
    if cos is not None and smap.slope is not None:
        out["slope"] = mi.Float((smap.slope.numpy() * cos).astype(np.float32))
    return dataclasses.replace(smap, **out)
