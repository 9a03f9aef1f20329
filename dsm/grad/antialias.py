"""The antialiased map: Worchel & Alexa's edge treatment, re-derived for a ray-cast map.

Worchel & Alexa ("Differentiable Shadow Mapping for Efficient Inverse Graphics", CVPR 2023,
section 4) render the shadow map with a differentiable rasterizer and pass it through that
rasterizer's analytic antialiasing (Laine et al., "Modular Primitives for High-Performance
Differentiable Rendering", SIGGRAPH Asia 2020), so that a texel next to a silhouette takes a
value that moves continuously with the silhouette; a pre-filter then spreads that change over
the shadow's edge. Without it, a texel's value is its centre ray's hit, which jumps when the
silhouette crosses the centre: the map's edge has no gradient.

Re-derived here for texels whose rays were traced:

- A *pair* is two texels next to each other in u or in v whose rays hit different shapes. The
  nearer hit (smaller depth) is the occluder; its triangle, projected into the map (the view's
  own projection, attached), contains the near texel's centre. The segment from the near centre
  to the far centre leaves that triangle through one edge; where that edge is a silhouette (a
  boundary edge of an open mesh, or an edge between a triangle facing the light and one facing
  away) it crosses the segment at a fraction ``a`` of the way (0 at the near centre, 1 at the far).
- Coverage along the segment is taken as a step at ``a``, each texel owning its half of the
  segment: if ``a < 1/2`` the far surface covers ``1/2 - a`` of the near texel's half, so the
  near texel's value moves toward the far one's by that weight; if ``a > 1/2`` the occluder
  covers ``a - 1/2`` of the far texel's half, and the far texel's value moves toward the near
  one's. A texel's value becomes ``x_T + sum_d w_d(T) (x_N(T,d) - x_T)`` over its four neighbours.
- The value is whatever the technique reads per texel: the depth test's result for one receiver
  (nearest, PCF, PCSS) or the moments (VSM, ESM, EVSM, MSM), as Worchel & Alexa antialias the
  moments before the blur. Moving the silhouette by ``da`` changes the treated texel by ``-da``
  of the difference: a linear reconstruction then integrates to the silhouette's true motion.

Where the segment leaves the near triangle through an inner edge (a quad's diagonal), the exit of
the triangle across it is taken (one step: a silhouette reached through two inner edges, near a
vertex of a fan, is not treated); pairs on one shape (a closed mesh's own silhouette over
itself) are not treated.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..scenes.spawn import NO_SHAPE
from .light import positional

# the four neighbours: (du, dv)
DIRECTIONS = ((1, 0), (-1, 0), (0, 1), (0, -1))


@dataclass
class EdgeWeights:
    """Per texel and direction (DIRECTIONS), the weight toward that neighbour's value (attached)."""
    weights: dict          # (du, dv) -> mi.Float per texel
    resolution: int
    pairs: int             # pairs treated (their weight may still be 0)
    structure: np.ndarray  # per texel: bit 0 its pair toward +u treated, bit 1 toward +v (the map's discrete structure)


def edge_neighbours(faces: np.ndarray) -> np.ndarray:
    """(m, 3) index of the triangle across edge c -> c+1 of each triangle, -1 on a boundary edge."""
    f = np.asarray(faces, np.int64)
    owner = {}
    for t, tri in enumerate(f):
        for c in range(3):
            owner.setdefault(tuple(sorted((tri[c], tri[(c + 1) % 3]))), []).append(t)
    out = np.full((len(f), 3), -1, np.int64)
    for t, tri in enumerate(f):
        for c in range(3):
            tris = owner[tuple(sorted((tri[c], tri[(c + 1) % 3])))]
            others = [o for o in tris if o != t]
            out[t, c] = others[0] if len(others) == 1 and len(tris) == 2 else -1
    return out


def _corners(buf, faces, tri, mask):
    """The three world corners of triangles ``tri`` of one shape (attached through ``buf``)."""
    out = []
    for c in range(3):
        vidx = dr.gather(mi.UInt32, mi.UInt32(np.asarray(faces[:, c], np.uint32)), tri, mask)
        out.append(dr.gather(mi.Point3f, buf, vidx, mask))
    return out


def _faces_light(corners, light):
    """Whether the triangle (its winding normal) faces the light."""
    p0, p1, p2 = corners
    n = dr.cross(p1 - p0, p2 - p0)
    toward = (p0 + p1 + p2) / 3.0 - light.position if positional(light) else light.direction
    return dr.dot(n, toward) < 0


def _crossing(c0, c1, a, b):
    """(s, hit): where segment c0 -> c1 (map, texels) crosses edge a -> b, as a fraction s of c0 -> c1."""
    r = (c1[0] - c0[0], c1[1] - c0[1])
    e = (b[0] - a[0], b[1] - a[1])
    den = r[0] * e[1] - r[1] * e[0]
    q = (a[0] - c0[0], a[1] - c0[1])
    safe = dr.select(den != 0, den, 1.0)
    s = (q[0] * e[1] - q[1] * e[0]) / safe
    t = (q[0] * r[1] - q[1] * r[0]) / safe
    return s, (den != 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)


def _exit(view, light, buf, faces, nbr, tri, mask, c0, c1):
    """Where segment c0 -> c1 leaves triangles ``tri`` (the crossing furthest along it): (s, whether that
    edge is a silhouette, the triangle across it (-1: none), whether any edge is crossed)."""
    corners = _corners(buf, faces, tri, mask)
    proj = [view.project_on(p) for p in corners]
    front = _faces_light(corners, light)
    n = dr.width(tri)
    s_out, sil, across = dr.full(mi.Float, -1.0, n), dr.zeros(mi.Bool, n), dr.full(mi.Int32, -1, n)
    for c in range(3):
        other = dr.gather(mi.Int32, mi.Int32(np.asarray(nbr[:, c], np.int32)), tri, mask)
        has = other >= 0
        o_corners = _corners(buf, faces, mi.UInt32(dr.maximum(other, 0)), mask & has)
        silhouette = ~has | (_faces_light(o_corners, light) != front)
        s, hit = _crossing(c0, c1, proj[c], proj[(c + 1) % 3])
        last = mask & hit & (dr.detach(s) > dr.detach(s_out))
        s_out = dr.select(last, s, s_out)
        sil = dr.select(last, silhouette, sil)
        across = dr.select(last, other, across)
    return s_out, sil, across, s_out >= 0


def _near_silhouette(view, triangles, light, shape, tri, c0, c1):
    """(a, treated) per pair: the fraction from the near centre c0 where the occluder's silhouette crosses
    toward c1, and whether it was found: the near triangle's exit edge, or, where that is an inner edge
    (a quad's diagonal), the exit edge of the triangle across it."""
    n = dr.width(shape)
    alpha = dr.full(mi.Float, 2.0, n)
    treated = dr.zeros(mi.Bool, n)
    for k, entry in enumerate(triangles):
        if entry is None:
            continue
        buf, faces = entry
        nbr = edge_neighbours(faces)
        mask = shape == k
        s1, sil1, across, found1 = _exit(view, light, buf, faces, nbr, tri, mask, c0, c1)
        hop = mask & found1 & ~sil1 & (across >= 0)
        s2, sil2, _, found2 = _exit(view, light, buf, faces, nbr, mi.UInt32(dr.maximum(across, 0)), hop, c0, c1)
        use2 = hop & found2 & (dr.detach(s2) >= dr.detach(s1))
        alpha = dr.select(mask & found1, dr.select(use2, s2, s1), alpha)
        treated = dr.select(mask & found1, dr.select(use2, sil2, sil1), treated)
    return alpha, treated & (alpha <= 1.0)


def edge_weights(amap, triangles, light) -> EdgeWeights:
    """The antialiasing weights of an attached map (``amap``: dsm.grad.build.AttachedMap); ``triangles``:
    per shape index, (flat vertex buffer, faces); ``light``: the kit's LightSpec, attached (facing of triangles)."""
    smap, view = amap.smap, amap.smap.view
    R = view.resolution
    idx = dr.arange(mi.UInt32, R * R)
    i, j = idx % R, idx // R
    weights, pairs, structure = {}, 0, np.zeros(R * R, np.uint8)
    for bit, (du, dv) in enumerate(((1, 0), (0, 1))):
        inside = (i + du < R) & (j + dv < R)
        other = dr.select(inside, idx + du + dv * R, idx)
        za, zb = dr.detach(smap.z1), dr.detach(dr.gather(mi.Float, smap.z1, other))
        sa, sb = smap.shape, dr.gather(mi.UInt32, smap.shape, other)
        a_near = za <= zb
        near_shape = dr.select(a_near, sa, sb)
        near_tri = dr.select(a_near, amap.prim, dr.gather(mi.UInt32, amap.prim, other))
        ca = (mi.Float(i) + 0.5, mi.Float(j) + 0.5)
        cb = (ca[0] + du, ca[1] + dv)
        c0 = tuple(dr.select(a_near, x, y) for x, y in zip(ca, cb))
        c1 = tuple(dr.select(a_near, y, x) for x, y in zip(ca, cb))
        pair = inside & (sa != sb) & (near_shape != NO_SHAPE)
        alpha, treated = _near_silhouette(view, triangles, light, dr.select(pair, near_shape, NO_SHAPE),
                                          near_tri, c0, c1)
        ok = pair & treated
        pairs += int(dr.count(ok).numpy().ravel()[0])
        # a pair switches on or off (a corner's segment passing an edge's end) without any texel changing
        # class: the treated texels' values jump, so a difference across it measures a jump, not a slope
        structure |= (ok.numpy().astype(np.uint8) << bit)
        w_near = dr.select(ok & (alpha < 0.5), 0.5 - alpha, 0.0)     # the near texel toward the far one
        w_far = dr.select(ok & (alpha >= 0.5), alpha - 0.5, 0.0)     # the far texel toward the near one
        w_a = dr.select(a_near, w_near, w_far)                       # texel idx toward idx + (du, dv)
        w_b = dr.select(a_near, w_far, w_near)                       # texel idx + (du, dv) toward idx
        weights[(du, dv)] = w_a
        back = dr.select((i >= du) & (j >= dv), idx - du - dv * R, idx)
        weights[(-du, -dv)] = dr.select((i >= du) & (j >= dv), dr.gather(mi.Float, w_b, back), 0.0)
    dr.eval(weights)             # a kernel of its own (see dsm.grad.build)
    return EdgeWeights(weights, R, pairs, structure)


def neighbour(idx, d, R: int):
    """Texel index of the neighbour of texels ``idx`` in direction ``d`` (clamped at the map's border)."""
    i, j = mi.Int32(idx % R), mi.Int32(idx // R)
    i2 = dr.clip(i + d[0], 0, R - 1)
    j2 = dr.clip(j + d[1], 0, R - 1)
    return mi.UInt32(j2 * R + i2)


def mix(values: list, ew: EdgeWeights) -> list:
    """Per-texel arrays (one per moment) with each texel moved toward its neighbours by the edge weights."""
    R = ew.resolution
    idx = dr.arange(mi.UInt32, R * R)
    out = []
    for x in values:
        y = x
        for d in DIRECTIONS:
            y = y + ew.weights[d] * (dr.gather(mi.Float, x, neighbour(idx, d, R)) - x)
        out.append(y)
    return out
