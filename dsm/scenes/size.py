"""How many triangles a scene holds, read before it is loaded (for the plan's memory estimate).

A PLY's header names its face count; an OBJ's faces are counted by their lines (a polygon of k
corners as k - 2 triangles is not resolved: a face line counts as one triangle, so a quad mesh
reads as half its triangles); an XML scene sums its ``ply`` and ``obj`` shapes (other shapes are
a handful of triangles or analytic); a built-in is generated.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

SMALL_SHAPE = 12          # a cube's triangles: an XML rectangle, disk or cube counts as this


def ply_triangles(path: Path) -> int:
    """The face count in a PLY's header (0 where it has none or cannot be read)."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return 0
    m = re.search(rb"element\s+face\s+(\d+)", head.split(b"end_header")[0])
    return int(m.group(1)) if m else 0


def obj_triangles(path: Path) -> int:
    """The face lines of an OBJ file (read in 16 MiB chunks; 0 where it cannot be read)."""
    n, tail = 0, b"\n"
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 24):
                n += (tail + chunk).count(b"\nf ")
                tail = chunk[-1:]
    except OSError:
        return 0
    return n


def xml_triangles(path: Path) -> int:
    """The triangles of an XML scene's mesh files (relative to its folder), SMALL_SHAPE per other shape."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return 0
    total = 0
    for shape in root.iter("shape"):
        kind = shape.get("type", "")
        name = next((s.get("value") for s in shape.iter("string") if s.get("name") == "filename"), None)
        if kind in ("ply", "obj") and name and "$" not in name:
            f = path.parent / name
            total += ply_triangles(f) if kind == "ply" else obj_triangles(f)
        else:
            total += SMALL_SHAPE
    return total


def file_triangles(path: Path) -> int:
    """The triangles of a scene file by its suffix."""
    suffix = Path(path).suffix.lower()
    return {".ply": ply_triangles, ".obj": obj_triangles, ".xml": xml_triangles}.get(suffix, lambda p: 0)(Path(path))
