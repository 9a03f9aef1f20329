"""A PLY file's header and face indices, read to refuse a damaged file Mitsuba would read past its end."""
from __future__ import annotations

from pathlib import Path

import numpy as np


PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


PLY_ORDER = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}


def ply_index_problem(path: Path, head: bytes, end: int) -> str | None:
    """A PLY face index outside its vertices, in words (None: all in range, or left to Mitsuba)."""
    # Mitsuba reads such a face past its vertex buffer (a segfault, not an error); a truncated
    # file or a header this does not read (lists before the faces, mixed polygon sizes) Mitsuba
    # reports itself
    try:
        fmt, elements = _ply_header(head[:end])
        data = head.index(b"\n", end) + 1
        counts, faces = _ply_faces(path, data, fmt, elements)
    except (ValueError, KeyError, IndexError, StopIteration):
        return None
    n = counts.get("vertex", 0)
    if faces is None or faces.size == 0:
        return None
    lo, hi = int(faces.min()), int(faces.max())
    if lo >= 0 and hi < n:
        return None
    worst = hi if hi >= n else lo
    which = f"face {int(np.flatnonzero((faces == worst).any(axis=1))[0])}" if faces.ndim == 2 else "a face"
    return f"{which} refers to vertex {worst} of {n} (indices 0 to {n - 1}): the file is damaged"


def _ply_header(text: bytes):
    """(format, [(element, count, [(name, type) or (name, (count type, item type))])]) of a PLY header."""
    fmt, elements = None, []
    for line in text.decode("ascii", "replace").splitlines():
        w = line.split()
        if w[:1] == ["format"]:
            fmt = w[1]
        elif w[:1] == ["element"]:
            elements.append((w[1], int(w[2]), []))
        elif w[:2] == ["property", "list"]:
            elements[-1][2].append((w[4], (PLY_TYPES[w[2]], PLY_TYPES[w[3]])))
        elif w[:1] == ["property"]:
            elements[-1][2].append((w[2], PLY_TYPES[w[1]]))
    if fmt not in PLY_ORDER:
        raise ValueError(fmt)
    return fmt, elements


def _ply_faces(path: Path, offset: int, fmt: str, elements):
    """({element: count}, the face element's vertex indices: an (n, k) array, or a flat one)."""
    counts = {name: n for name, n, _ in elements}
    if fmt == "ascii":
        return counts, _ply_ascii_faces(path.read_bytes()[offset:], elements)
    order = PLY_ORDER[fmt]
    buf = np.memmap(path, np.uint8, mode="r")
    for name, n, props in elements:
        if name == "face":
            return counts, _ply_binary_faces(buf, offset, n, props, order)
        if any(isinstance(t, tuple) for _, t in props):
            raise ValueError("a list before the faces")      # rare: Mitsuba's own checks only
        offset += n * sum(np.dtype(t).itemsize for _, t in props)
    return counts, None


def _ply_binary_faces(buf, offset, n, props, order):
    # every face with the first face's corner count (triangles, or quads): one strided read
    first = offset
    fields = []
    for name, t in props:
        if isinstance(t, tuple):
            k = int(np.frombuffer(buf, order + t[0], 1, first)[0])
            fields += [(name + "#n", order + t[0]), (name, order + t[1], (k,))]
            first += np.dtype(t[0]).itemsize
        else:
            fields.append((name, order + t))
            first += np.dtype(t).itemsize
    rec = np.frombuffer(buf, np.dtype(fields), n, offset)      # ValueError when truncated
    lists = [name for name, t in props if isinstance(t, tuple)]
    if not all((rec[f + "#n"] == rec[f + "#n"][0]).all() for f in lists):
        raise ValueError("faces of several sizes")             # Mitsuba's own checks only
    key = "vertex_indices" if "vertex_indices" in lists else lists[0]
    return rec[key].astype(np.int64)


def _ply_ascii_faces(body: bytes, elements):
    rows = iter(l.split() for l in body.splitlines() if l.strip())
    for name, n, props in elements:
        if name != "face":
            for _ in range(n):
                next(rows)                                     # StopIteration: truncated
            continue
        out = []
        for _ in range(n):
            w, i = next(rows), 0
            for pname, t in props:
                k = int(w[i]) + 1 if isinstance(t, tuple) else 1
                if isinstance(t, tuple) and pname in ("vertex_indices", "vertex_index"):
                    out += [int(x) for x in w[i + 1:i + k]]
                i += k
        return np.asarray(out, np.int64)
    return None


def ply_positions(path: Path) -> np.ndarray:
    """A PLY file's vertex positions (n, 3), float64, read with numpy (vertices before other elements)."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    end = head.index(b"end_header")
    fmt, elements = _ply_header(head[:end])
    offset = head.index(b"\n", end) + 1
    name, n, props = elements[0]
    if name != "vertex" or any(isinstance(t, tuple) for _, t in props):
        raise ValueError(f"{path}: the first element is not a plain vertex list")
    if fmt == "ascii":
        rows = path.read_bytes()[offset:].splitlines()[:n]
        table = np.array([r.split()[:len(props)] for r in rows], np.float64)
    else:
        dtype = np.dtype([(p, PLY_ORDER[fmt] + t) for p, t in props])
        table = np.frombuffer(path.read_bytes(), dtype, n, offset)
        return np.stack([table[c].astype(np.float64) for c in "xyz"], axis=1)
    names = [p for p, _ in props]
    return table[:, [names.index(c) for c in "xyz"]]
