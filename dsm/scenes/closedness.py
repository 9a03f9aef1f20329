"""Closed or open: whether a mesh bounds a solid, so back-face culling may apply to it.

A mesh is closed when, after welding vertices that share a position, every edge is shared by
exactly two triangles that traverse it in opposite directions (a consistently wound,
manifold surface without boundary). Anything else is open, with the reason reported:
boundary edges, non-manifold edges (three or more triangles, or duplicated triangles) or
inconsistent winding. Weiskopf & Ertl 2003 cull back faces of closed meshes only.

A closed mesh wound inward (negative enclosed volume, like a room's walls seen from inside)
is reported as such: to back-face culling its solid is everything outside it, so a light
outside it would see through it. The runner therefore never culls it (it is culled as an open
surface is: not at all), and run.json says so.
"""
from __future__ import annotations

import numpy as np


def closedness(verts: np.ndarray, faces: np.ndarray) -> tuple[bool, str]:
    """(closed, reason) of a triangle mesh: each welded edge shared by two oppositely wound triangles, or why not."""
    verts = np.asarray(verts, np.float64).reshape(-1, 3)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return False, "no triangles"
    weld = weld_ids(verts)
    f = weld[faces]
    degenerate = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    f = f[~degenerate]
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    # an edge (a, b) of welded ids as one integer a * n + b: a 1-D sort, where unique(axis=0) sorts rows
    # as opaque records (10 times slower on the real meshes); the counts are the same
    n = np.int64(weld.max() + 1)
    undirected = np.sort(directed, axis=1)
    _, counts = np.unique(undirected[:, 0] * n + undirected[:, 1], return_counts=True)
    boundary, nonmanifold = int((counts == 1).sum()), int((counts > 2).sum())
    _, dcounts = np.unique(directed[:, 0] * n + directed[:, 1], return_counts=True)
    same_direction = int((dcounts > 1).sum())
    problems = []
    if boundary:
        problems.append(f"{boundary} boundary edges")
    if nonmanifold:
        problems.append(f"{nonmanifold} non-manifold edges")
    if same_direction:
        problems.append(f"{same_direction} edges with inconsistent winding")
    if int(degenerate.sum()):
        problems.append(f"{int(degenerate.sum())} degenerate triangles (ignored)")
    closed = not (boundary or nonmanifold or same_direction)
    if closed and not problems:
        p = np.zeros((weld.max() + 1, 3))
        p[weld.ravel()] = verts
        volume = float(np.einsum("ij,ij->i", p[f[:, 0]], np.cross(p[f[:, 1]], p[f[:, 2]])).sum() / 6.0)
        return closed, "closed" if volume >= 0 else "closed, wound inward (negative volume: its solid is outside it)"
    return closed, "; ".join(problems) or "closed"


def weld_ids(verts: np.ndarray) -> np.ndarray:
    """Per vertex, one id shared by every vertex at the same position (positions compared as numbers,
    as ``np.unique(verts, axis=0)`` compares them: -0.0 equals 0.0); ids count up in that order."""
    order = np.lexsort(verts.T[::-1])
    sorted_v = verts[order]
    starts = np.concatenate([[True], np.any(sorted_v[1:] != sorted_v[:-1], axis=1)])
    ids = np.empty(len(verts), np.int64)
    ids[order] = np.cumsum(starts) - 1
    return ids


def shape_closedness(shape) -> tuple[bool, str]:
    """Closedness of a Mitsuba shape: meshes by their edges, analytic shapes by kind."""
    if shape.is_mesh():
        # the buffers, not mi.traverse: an XML rectangle is a mesh that exposes only to_world
        return closedness(np.array(shape.vertex_positions_buffer()), np.array(shape.faces_buffer()))
    kind = type(shape).__name__.lower()
    if "sphere" in kind:
        return True, "analytic sphere"
    return False, f"analytic {kind} (treated as open)"
