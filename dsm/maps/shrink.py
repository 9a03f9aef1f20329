"""Caster shrinking: the map is cast against meshes moved inward along their welded vertex normals.

``[map] shrink = d`` (world units): before a map is built, every vertex of every mesh moves by
``-d n_v``, ``n_v`` its welded vertex normal: the area-weighted sum of the winding normals of
the triangles around every vertex at the same position (position-welded, so a mesh stored with
split vertices, as OBJ and PLY files often are, moves as one surface; face normals would crack
it at every edge), normalized. Engines do this at the caster (Unity's "normal bias": "shadow
caster surfaces are pushed inwards along their normals"; godotengine/godot-proposals#4517). A
closed mesh wound outward shrinks; an open one (a ground quad) moves against its winding
normal. Only the map's casters move: the G-buffer, the receivers and the exact reference use
the scene as it is. The shrunk copy keeps the scene's shape order, so the map's shape ids are
the scene's.
"""
from __future__ import annotations

import numpy as np

from ..scenes.closedness import weld_ids


def welded_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per vertex (n, 3), float64: the normalized area-weighted winding normal of every triangle at
    its position (0 where they cancel)."""
    v = np.asarray(verts, np.float64)
    f = np.asarray(faces, np.int64)
    weld = weld_ids(v)                                        # one id per distinct position
    area2 = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])   # twice the area times the normal
    acc = np.zeros((weld.max() + 1, 3))
    for k in range(3):
        np.add.at(acc, weld[f[:, k]], area2)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    n = np.divide(acc, norm, out=np.zeros_like(acc), where=norm > 0)
    return n[weld]


def shrunk_vertices(verts: np.ndarray, faces: np.ndarray, distance: float) -> np.ndarray:
    """The vertices moved by ``distance`` against their welded normals (float64)."""
    return np.asarray(verts, np.float64) - distance * welded_normals(verts, faces)


def shrunk_scene(scene, distance: float):
    """A Mitsuba scene of ``scene``'s shapes, each mesh's vertices shrunk by ``distance`` (same shape
    order); ValueError for a shape that is not a triangle mesh."""
    import mitsuba as mi
    from ..scenes.geometry import make_mesh
    d = {"type": "scene"}
    ids = []
    for i, shape in enumerate(scene.shapes()):
        if not shape.is_mesh():
            raise ValueError(f"map.shrink: shape {shape.id() or i} is not a triangle mesh; shrinking moves mesh "
                             "vertices (remove map.shrink or give the shape as a mesh)")
        params = mi.traverse(shape)
        verts = np.asarray(params["vertex_positions"].numpy(), np.float64).reshape(-1, 3)
        faces = np.asarray(params["faces"].numpy(), np.int64).reshape(-1, 3)
        key = shape.id() if shape.id() and shape.id() not in d else f"shrunk_{i:06d}"    # the key is the id
        ids.append(key)
        d[key] = make_mesh(key, shrunk_vertices(verts, faces, distance), faces)
    out = mi.load_dict(d, optimize=False)
    if [s.id() for s in out.shapes()] != ids:          # the map's shape ids index scene.shapes()
        raise RuntimeError("map.shrink: the shrunk scene's shapes came out in another order")
    return out
