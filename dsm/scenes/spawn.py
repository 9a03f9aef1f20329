"""Rays that leave a surface: offsets from a bound on the hit point's floating-point error.

A hit point ``p`` computed in float32 lies off the true surface by rounding alone. A ray that
leaves ``p`` must start beyond that error, or it re-hits the surface it left (false
occlusion); it must not start much further, or it skips a surface that is really there (a
shadow lost). Mitsuba's own rule, ``(1 + max|p|) * 8.94e-5``, is about 1500 float32 ulps of
the coordinates: at (2000, 1500, 100) it is 0.36, more than the 0.2 gap of the floating
plate, though float32 resolves that gap there a thousand times over.

The bound here follows pbrt-v4 (Pharr, Jakob & Humphreys, "Physically Based Rendering",
4th ed., section 6.8): a triangle's hit point is interpolated from its vertices,
``p = b0 p0 + b1 p1 + b2 p2``, so its distance from the triangle's plane is at most
``gamma(7) * max|p_i|`` per coordinate, with ``gamma(n) = n u / (1 - n u)`` and
``u = 2^-24``; errors in the barycentrics only slide ``p`` within the plane. Embree's own
ray/triangle test adds an error of a few ulps of the triangle's extent around the origin of
the next ray. The offset is

    delta = SAFETY * u * (max|p| + extent),    extent = max_k |p_k - p| (the triangle's size)

along the geometric normal, toward the side the ray leaves by. ``SAFETY`` = 32 covers the
seven ulps of the interpolation, the rounding of the new origin (half an ulp of ``|p|``) and
Embree's test with a factor of about three to spare; ``tests/test_reference.py`` measures
the hit points' distance from the true surface in float64 over many rays and positions and
checks it stays below delta / 3. Non-triangle shapes (Mitsuba's analytic spheres,
rectangles, disks) take the scene's largest coordinate as the extent.

A point ``r`` from the light is exact where the scene's gaps exceed delta: about
``2^-24 * 32 * (|p| + extent)``; the reference therefore stays exact at a distance ``D``
from the origin as long as the smallest gap is above ``2e-6 * (D + extent)``.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

# Embree's coherent traversal resolves a ray near a silhouette differently depending on which
# rays share its packet (the tile it was cast in, the compaction of a layered search, the
# CPU's vector width); its incoherent traversal gives every ray the same hit wherever it is
# cast (docs/design.md, *Results that do not depend on the machine*).
COHERENT = False     # the map's, the G-buffer's and the light samples' casts

U32 = 2.0 ** -24     # float32 unit roundoff
SAFETY = 32.0


def bound(p, extent=0.0):
    """The offset rule itself: SAFETY * u * (max|p| + extent)."""
    return SAFETY * U32 * (dr.max(dr.abs(p)) + extent)


def error_bound(si, other_extent):
    """The offset ``delta`` of each hit (Float): SAFETY * u * (max|p| + extent), the extent being
    the triangle's own size for meshes and ``other_extent`` for other shapes."""
    valid = si.is_valid()
    tri = valid & si.shape.is_mesh()
    mesh = mi.MeshPtr(si.shape)
    fi = mesh.face_indices(si.prim_index, tri)
    tri_extent = dr.zeros(mi.Float, dr.width(si.p))
    for k in range(3):
        vk = mesh.vertex_position(fi[k], tri)
        tri_extent = dr.maximum(tri_extent, dr.max(dr.abs(vk - si.p)))
    extent = dr.select(tri, tri_extent, other_extent)
    return bound(si.p, extent)


NO_SHAPE = 0xFFFFFFFF


def shape_table(scene, force: bool = False):
    """The index into ``scene.shapes()`` of each shape's registry id (UInt32, NO_SHAPE between),
    or None where the hit's own ``shape_index`` is that index.

    A preliminary hit names its shape by pointer (``pi.shape``, or ``pi.instance`` for a hit
    inside an instance). Its ``shape_index`` is the index only with Embree (``llvm_ad_rgb``)
    and only outside instances: OptiX (``cuda_ad_rgb``) leaves it 0, and Embree gives an
    instance's inner shape. :func:`hit_shape` reads the pointer through this table there (and
    everywhere with ``force``); elsewhere ``shape_index`` serves and costs no table read."""
    shapes = scene.shapes()
    if not force and not mi.variant().startswith("cuda") and \
            not any(s.class_name() == "Instance" for s in shapes):
        return None
    if not shapes:
        return mi.UInt32(np.array([NO_SHAPE], np.uint32))
    ids = np.asarray(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shapes)).numpy(), np.int64)
    table = np.full(int(ids.max()) + 1, NO_SHAPE, np.uint32)
    table[ids] = np.arange(len(shapes), dtype=np.uint32)
    return mi.UInt32(table)


def hit_shape(pi, valid, table):
    """The index into ``scene.shapes()`` of each preliminary hit (the instance's for a hit inside
    one), NO_SHAPE where ``valid`` is False or the hit names no listed shape. ``table``:
    :func:`shape_table` of the scene (None: Embree's ``shape_index`` as it is)."""
    if table is None:
        return dr.select(valid, pi.shape_index, NO_SHAPE)
    inst = dr.reinterpret_array(mi.UInt32, pi.instance)
    ids = dr.select(inst != 0, inst, dr.reinterpret_array(mi.UInt32, pi.shape))
    known = valid & (ids < dr.width(table))
    return dr.select(known, dr.gather(mi.UInt32, table, ids, known), NO_SHAPE)


# floats per triangle in ShapeTables.tri_pos: its nine coordinates padded to a power of two, so
# that Dr.Jit reads a triangle as one packet (a 64-byte cache line) instead of nine gathers: the
# first layer's kernel time over a bare cast fell from 1.44x to 1.33x (plane_box) and 1.34x to
# 1.21x (bunny) at 2048^2 on 2 cores, for 28 bytes more per triangle
TRI_STRIDE = 16


class ShapeTables(tuple):
    """(extents, is_mesh) per shape, as :func:`error_bound_by_shape` reads them, with the meshes'
    triangles for a hit's vertices without a surface interaction: ``tri_pos`` (Float, the nine
    coordinates of each triangle of every mesh, p0 p1 p2, padded to TRI_STRIDE floats, in shape
    order: a triangle's vertices are one aligned packet read, not a face read and then three
    vertex reads) and ``face_offset``
    (UInt32 per shape: its first triangle); both None when a shape is not a triangle mesh.
    ``by_id``: :func:`shape_table` (None where ``shape_index`` serves)."""
    tri_pos = face_offset = None
    by_id = None


def shape_extents(scene) -> ShapeTables:
    """Per shape index of ``scene.shapes()``: the largest extent (max-norm of an edge) of any of
    its triangles, a bound on ``max_k |p_k - p|`` for every hit on it; 0 for non-meshes. One
    numpy pass over the meshes, so a loop of continuation rays needs no per-ray vertex fetch;
    computed once per scene (it also gathers the buffers of :class:`ShapeTables`)."""
    out, soup, first_face = [], [], []
    n_face = 0
    for shape in scene.shapes():
        first_face.append(n_face)
        if not shape.is_mesh():
            out.append(0.0)
            continue
        v32 = np.asarray(shape.vertex_positions_buffer(), np.float32).reshape(-1, 3)
        f = np.asarray(shape.faces_buffer(), np.int64).reshape(-1, 3)
        tri32 = np.zeros((len(f), TRI_STRIDE), np.float32)
        tri32[:, :9] = v32[f].reshape(-1, 9)
        soup.append(tri32.reshape(-1))
        n_face += len(f)
        if len(f) == 0:
            out.append(0.0)
            continue
        tri = v32.astype(np.float64)[f]
        edges = np.abs(tri - np.roll(tri, 1, axis=1)).max(axis=(1, 2))
        out.append(float(edges.max()))
    meshes = [s.is_mesh() for s in scene.shapes()]
    tables = ShapeTables((mi.Float(np.asarray(out, np.float32)), mi.Bool(np.array(meshes, bool))))
    tables.by_id = shape_table(scene)
    if all(meshes) and soup:
        tables.tri_pos = mi.Float(np.concatenate(soup))
        tables.face_offset = mi.UInt32(np.asarray(first_face, np.uint32))
    return tables


def mesh_hit(pi, shape, tables, active):
    """(p, n) of a preliminary intersection on a triangle mesh from the meshes' buffers: the hit
    point interpolated from the vertices and the winding normal, the same arithmetic (and bits)
    as Mitsuba's ``compute_surface_interaction`` with ``RayFlags.Minimal``, without its call
    through the shape. ``shape``: the hit's index into ``scene.shapes()`` (:func:`hit_shape`)."""
    tri = dr.gather(mi.UInt32, tables.face_offset, shape, active) + pi.prim_index
    c = dr.gather(mi.ArrayXf, tables.tri_pos, tri, active, shape=(TRI_STRIDE, dr.width(tri)))
    p0, p1, p2 = (mi.Point3f(c[3 * k], c[3 * k + 1], c[3 * k + 2]) for k in range(3))
    b1, b2 = pi.prim_uv.x, pi.prim_uv.y
    b0 = 1.0 - b1 - b2
    p = dr.fma(p0, b0, dr.fma(p1, b1, p2 * b2))
    n = dr.normalize(dr.cross(p1 - p0, p2 - p0))
    return p, n


def error_bound_by_shape(p, shape_index, tables, other_extent):
    """:func:`error_bound` with each mesh's largest triangle as the extent (``tables`` from
    :func:`shape_extents`): a little looser, and no per-ray access to the triangle."""
    extents, is_mesh = tables[0], tables[1]
    hit = shape_index != NO_SHAPE                  # a miss reads nothing (out of bounds: a fault on CUDA)
    ext = dr.gather(mi.Float, extents, shape_index, hit)
    mesh = dr.gather(mi.Bool, is_mesh, shape_index, hit)
    return bound(p, dr.select(mesh, ext, other_extent))


def offset_origin(p, n, d, delta):
    """``p`` moved by ``delta`` along ``n``, to the side ``d`` leaves by."""
    return p + n * dr.select(dr.dot(n, d) >= 0, delta, -delta)


def ray_along(si, n, d, delta) -> mi.Ray3f:
    """A ray leaving the hit ``si`` in direction ``d`` (unbounded)."""
    return mi.Ray3f(offset_origin(si.p, n, d, delta), d)


def ray_to(si, n, target, delta) -> mi.Ray3f:
    """A segment from the hit ``si`` toward the point ``target``, stopping ``delta`` short of it
    (measured in the target's own ulps as well, so a light far from the origin is not hit)."""
    o = offset_origin(si.p, n, target - si.p, delta)
    d = target - o
    dist = dr.norm(d)
    short = bound(target)
    return mi.Ray3f(o, d / dist, dr.maximum(dist - short, 0.0), 0.0, mi.Color0f())


def rays_np(o: np.ndarray, d: np.ndarray, maxt: np.ndarray | None = None) -> mi.Ray3f:
    """A ray array from (n, 3) numpy origins and directions (and per-ray ``maxt``), built from plain
    float32 buffers, not gathered from a traced one (gathering a layer's rays and tracing them again
    corrupted memory now and then on the room's cube map under the LLVM backend)."""
    f32 = lambda a: mi.Float(np.ascontiguousarray(a, np.float32))
    ray = mi.Ray3f(mi.Point3f(*(f32(o[:, k]) for k in range(3))), mi.Vector3f(*(f32(d[:, k]) for k in range(3))))
    if maxt is not None:
        ray.maxt = f32(maxt)
    return ray
