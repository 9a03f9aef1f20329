"""Triangle meshes made in code (numpy, float64) and as Mitsuba meshes: quads, boxes, prisms, a
smoothed polycube; rotations, unit vectors and the float32 limits of a triangle's normal."""
from __future__ import annotations

import math

import numpy as np


# Mitsuba computes a triangle's normal as normalize(cross(e1, e2)) in float32, squaring the cross
# product's length: above sqrt(FLT_MAX) = 1.8e19 it overflows to a zero normal (plane_box, whose
# largest |e1 x e2| is 64 at scale 1, loses its receivers between scale 5e8 and 7e8), below
# sqrt(FLT_MIN) = 1.1e-19 it flushes to zero and the normal is NaN (the unit box at scale 1e-10).
CROSS_MAX = 1e19


CROSS_MIN = 2e-19


def cross_lengths(verts, faces) -> np.ndarray:
    """|e1 x e2| (twice the area) of every triangle, in float64."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    return np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def quad(center, u_half, v_half):
    """Two triangles spanning center +- u_half +- v_half, normal along u x v."""
    c, u, v = (np.asarray(a, float) for a in (center, u_half, v_half))
    verts = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]])


def box(lo, hi):
    """A closed box, outward-facing triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return verts, faces


def prism(profile_xz, y0, y1, fan_center: int):
    """A closed prism: a simple polygon in the xz plane (counter-clockwise seen from -y), extruded along y.

    The caps are a fan from vertex ``fan_center``, which must see the whole polygon.
    """
    prof = np.asarray(profile_xz, float)
    n = len(prof)
    front = np.column_stack([prof[:, 0], np.full(n, y0), prof[:, 1]])
    back = np.column_stack([prof[:, 0], np.full(n, y1), prof[:, 1]])
    verts = np.vstack([front, back])
    faces = []
    order = [(fan_center + k) % n for k in range(n)]
    for a, b in zip(order[1:-1], order[2:]):
        faces.append([fan_center, b, a])              # front cap faces -y
        faces.append([n + fan_center, n + a, n + b])  # back cap faces +y
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    return verts, np.array(faces)[:, ::-1]   # outward: a counter-clockwise (x, z) profile winds inward


def make_mesh(name: str, verts: np.ndarray, faces: np.ndarray):
    """A Mitsuba mesh ``name`` of vertex positions ``verts`` (n, 3) and triangles ``faces`` (m, 3)."""
    import mitsuba as mi
    mesh = mi.Mesh(name, len(verts), len(faces))
    params = mi.traverse(mesh)
    with np.errstate(over="ignore"):     # beyond float32: inf, refused by check_loaded in one line
        params["vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    params.update()
    return mesh


def normalize(v):
    """``v`` as a unit vector (float64); a zero or non-finite vector is a ValueError."""
    v = np.asarray(v, float)
    n = float(np.linalg.norm(v))
    if not (n > 0 and math.isfinite(n)):
        raise ValueError(f"cannot normalize the vector {tuple(float(c) for c in v)}: it is zero or not finite")
    return tuple(float(c) for c in v / n)


def polycube(xs, ys, zs, solid):
    """The boundary of a union of grid cells as outward-wound quads (welded vertices):
    ``solid[i, j, k]`` fills the cell [xs[i], xs[i+1]] x [ys[j], ys[j+1]] x [zs[k], zs[k+1]]."""
    solid = np.asarray(solid, bool)
    nx, ny, nz = solid.shape
    vid = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k
    S = np.pad(solid, 1)
    quads = []
    for i, j, k in zip(*np.nonzero(solid)):
        if not S[i, j + 1, k + 1]:
            quads.append([vid(i, j, k), vid(i, j, k + 1), vid(i, j + 1, k + 1), vid(i, j + 1, k)])
        if not S[i + 2, j + 1, k + 1]:
            quads.append([vid(i + 1, j, k), vid(i + 1, j + 1, k), vid(i + 1, j + 1, k + 1), vid(i + 1, j, k + 1)])
        if not S[i + 1, j, k + 1]:
            quads.append([vid(i, j, k), vid(i + 1, j, k), vid(i + 1, j, k + 1), vid(i, j, k + 1)])
        if not S[i + 1, j + 2, k + 1]:
            quads.append([vid(i, j + 1, k), vid(i, j + 1, k + 1), vid(i + 1, j + 1, k + 1), vid(i + 1, j + 1, k)])
        if not S[i + 1, j + 1, k]:
            quads.append([vid(i, j, k), vid(i, j + 1, k), vid(i + 1, j + 1, k), vid(i + 1, j, k)])
        if not S[i + 1, j + 1, k + 2]:
            quads.append([vid(i, j, k + 1), vid(i + 1, j, k + 1), vid(i + 1, j + 1, k + 1), vid(i, j + 1, k + 1)])
    X, Y, Z = np.meshgrid(np.asarray(xs, float), np.asarray(ys, float), np.asarray(zs, float), indexing="ij")
    verts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    used, inv = np.unique(np.array(quads), return_inverse=True)
    return verts[used], inv.reshape(-1, 4)


def catmull_clark(verts, quads):
    """One Catmull-Clark step of a closed quad mesh: four quads per quad, wound as their parent."""
    V, Q = np.asarray(verts, float), np.asarray(quads, np.int64)
    nv, nq = len(V), len(Q)
    face_pt = V[Q].mean(1)
    edges = np.stack([Q, np.roll(Q, -1, axis=1)], -1).reshape(-1, 2)       # quad f's edge k: (Q[f,k], Q[f,k+1])
    uniq, inv = np.unique(np.sort(edges, 1), axis=0, return_inverse=True)
    inv = inv.ravel()
    fsum = np.zeros((len(uniq), 3))
    np.add.at(fsum, inv, np.repeat(face_pt, 4, axis=0))
    edge_pt = (V[uniq[:, 0]] + V[uniq[:, 1]] + fsum) / 4                    # two ends + two face points
    valence = np.zeros(nv)
    np.add.at(valence, uniq.ravel(), 1)
    F = np.zeros((nv, 3))
    np.add.at(F, Q.ravel(), np.repeat(face_pt, 4, axis=0))
    mid = (V[uniq[:, 0]] + V[uniq[:, 1]]) / 2
    R = np.zeros((nv, 3))
    np.add.at(R, uniq[:, 0], mid)
    np.add.at(R, uniq[:, 1], mid)
    n = valence[:, None]
    moved = (F / n + 2 * R / n + (n - 3) * V) / n
    E = inv.reshape(nq, 4) + nv
    C = np.arange(nq) + nv + len(uniq)
    out = [np.stack([Q[:, k], E[:, k], C, E[:, (k - 1) % 4]], 1) for k in range(4)]
    return np.vstack([moved, edge_pt, face_pt]), np.concatenate(out)


def double_torus(levels: int = 3):
    """A closed, outward-wound genus-2 triangle mesh: a slab with two square holes (a polycube of
    13 cells) smoothed by Catmull-Clark; 100 * 4**levels triangles, centred, about 2.4 x 1.4 x 0.5."""
    solid = np.ones((5, 3, 1), bool)
    solid[1, 1, 0] = solid[3, 1, 0] = False
    v, q = polycube([0, 1, 3, 4, 6, 7], [0, 1, 3, 4], [0, 1.5], solid)
    for _ in range(levels):
        v, q = catmull_clark(v, q)
    v = (v - (v.max(0) + v.min(0)) / 2) * 0.35
    return v, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def rotation(axis, angle_deg):
    """The 3 x 3 rotation by ``angle_deg`` degrees about ``axis`` (Rodrigues' formula)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * (k @ k)
