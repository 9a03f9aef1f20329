"""Mipmapped moment maps (``[map] mipmaps = true``): the chain of 2 x 2 means of the blurred,
stored moments, and a fetch that reads it at the receiver's camera-pixel footprint, linearly
between the two nearest levels (a GPU's trilinear minification, each level read at its nearest
texel as the kit's fetch reads the map).

A level halves the previous one per side (an odd side padded by its edge texel), each face apart
(no mean crosses a cube seam), down to one texel, each level stored in the map's format. The level
of a receiver is lambda = log2 of its footprint in texels: its camera pixel's area on its surface
(the pinhole's solid angle (2 tan_x / W)^2 cos^3 over the surface's cosine to the view ray, as
dsm.scenes.camera.Camera.pixel_area), projected along the light onto the map (times |n . l|),
over the texel's area at the receiver, square-rooted; below one texel lambda is 0 (the map
itself). Moments are linear, so the blend of two levels' moments is the moments of the blend.
Receivers without a known camera (rx.camera None) read level 0.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def chain(x: np.ndarray, faces: int, R: int, stored) -> list:
    """The levels after level 0 of per-texel values ``x`` (faces * R^2, float64): (side, values
    stored by ``stored``) each, down to a side of 1."""
    out, img = [], x.reshape(faces, R, R)
    while img.shape[1] > 1:
        if img.shape[1] % 2:
            img = np.pad(img, ((0, 0), (0, 1), (0, 1)), mode="edge")
        r = img.shape[1] // 2
        img = stored(img.reshape(faces, r, 2, r, 2).mean(axis=(2, 4)).reshape(-1)).reshape(faces, r, r)
        out.append((r, img.reshape(-1)))
    return out


def footprint_level(rx, levels: int):
    """lambda per receiver, in [0, levels - 1]: log2 of its camera pixel's footprint in texels of the map."""
    cam = rx.camera
    if cam is None or levels == 1:
        return dr.zeros(mi.Float, dr.width(rx.u_map))
    q = rx.p_world - mi.Point3f(*(dr.opaque(mi.Float, float(c)) for c in cam.origin))
    dist = dr.norm(q)
    cos_a = dr.dot(q, mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in cam.forward))) / dist
    omega = dr.opaque(mi.Float, (2.0 * cam.tan_x / cam.width) ** 2) * cos_a * cos_a * cos_a
    cos_n = dr.abs(dr.dot(rx.n_world, q)) / dist
    area = omega * dist * dist / dr.maximum(cos_n, 1e-12) * dr.abs(dr.dot(rx.n_world, rx.to_light))
    texels2 = area / (rx.texel_world * rx.texel_world)
    lam = 0.5 * dr.log2(dr.maximum(texels2, 1.0))
    return dr.clip(dr.select(dr.isfinite(lam), lam, 0.0), 0.0, float(levels - 1))


def packed(chains: list) -> tuple:
    """(per moment one mi.Float of its levels after 0 end to end, their offsets (UInt32), sides
    (UInt32), the halving of each level (Float)) of ``chains``: chain()'s levels, one list per moment."""
    sizes = [v.size for _, v in chains[0]]
    offsets = np.cumsum([0] + sizes[:-1]).astype(np.uint32)
    values = [mi.Float(np.concatenate([v for _, v in c]).astype(np.float32)) for c in chains]
    sides = np.array([r for r, _ in chains[0]], np.uint32)
    halving = np.array([2.0 ** -(i + 1) for i in range(len(sides))], np.float32)
    return values, mi.UInt32(offsets), mi.UInt32(sides), mi.Float(halving)


def fetch_level(mip, rx, level, base_b: list) -> list:
    """The moments of level ``level`` (Int32 per receiver, >= 0) at each receiver's nearest texel
    there; level 0 is ``base_b`` (the map's own fetch)."""
    values, offsets, sides, halving = mip
    k = mi.UInt32(dr.maximum(level - 1, 0))
    side = dr.gather(mi.UInt32, sides, k)
    off = dr.gather(mi.UInt32, offsets, k)
    scale = dr.gather(mi.Float, halving, k)
    s1 = mi.Int32(side) - 1
    i = dr.clip(mi.Int32(dr.floor(rx.u_map * scale)), 0, s1)
    j = dr.clip(mi.Int32(dr.floor(rx.v_map * scale)), 0, s1)
    idx = off + (rx.face * side + mi.UInt32(j)) * side + mi.UInt32(i)
    top = level == 0
    return [dr.select(top, b0, dr.gather(mi.Float, v, idx, ~top)) for b0, v in zip(base_b, values)]


def blend(mip, rx, base_b: list) -> list:
    """The moments at the receiver's footprint: levels floor(lambda) and the next, mixed linearly
    (``base_b``: level 0 fetched, the moments of t = 1 beyond a directional map kept there)."""
    n = dr.width(mip[2]) + 1
    lam = footprint_level(rx, n)
    l0 = mi.Int32(dr.floor(lam))
    l1 = dr.minimum(l0 + 1, n - 1)
    f = lam - mi.Float(l0)
    a = fetch_level(mip, rx, l0, base_b)
    b = fetch_level(mip, rx, l1, base_b)
    # where f is 0 the lower level alone (0 * inf would be NaN for an overflowed half)
    return [dr.select(f > 0, x + f * (y - x), x) for x, y in zip(a, b)]
