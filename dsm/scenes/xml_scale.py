"""A Mitsuba 3 XML scene in other units and elsewhere: every top-level shape, sensor and emitter
scaled about the origin, then moved, before loading, so an XML scene takes ``scale`` and
``translate`` as a mesh file does.

Mitsuba applies a ``<transform>``'s children in the order listed (each one left-multiplies what
came before), so appending ``<scale value="s"/>`` to a shape's ``to_world`` scales it after its
own placement: world' = S world (then ``<translate>``: world' = T S world). A sensor or an
emitter may not carry a scale (Mitsuba refuses it in a camera's transform), so theirs is
conjugated, T S M S^-1: the same orientation, its position times s, then moved. An element
without a ``to_world`` gets one holding only the scale (and move); a point emitter given by
``position`` has that point scaled and moved instead; a sensor's near and far clip planes are
distances and are scaled with it (Mitsuba's defaults, 0.01 and 10000, where the file gives none).
A directional emitter's direction and an environment's infinite extent do not change.
Shape groups are left alone (their instances carry the transforms) and an ``<include>`` is refused:
its elements would stay in the file's units.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

SENSOR_CLIPS = {"near_clip": 1e-2, "far_clip": 1e4}     # Mitsuba's perspective sensor defaults


def scaled_text(path: Path, scale: float, translate=(0.0, 0.0, 0.0)) -> str:
    """The XML of ``path`` with every top-level shape, sensor and emitter scaled by ``scale``, then
    moved by ``translate`` (world units after the scale)."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:          # said as Mitsuba's loader says it (the caller names the file)
        raise ValueError(f"parsing of the XML file failed: {e}") from None
    if root.find(".//include") is not None:
        raise ValueError("an <include> would keep its elements in the file's units: inline it to give a scale")
    scale, move = float(scale), tuple(float(c) for c in translate)
    for el in root:
        if el.tag == "shape" and el.get("type") != "shapegroup":
            _scale_transform(el, scale, move)
        elif el.tag == "sensor":
            _scale_transform(el, scale, move, conjugate=True)
            _scale_clips(el, scale)
        elif el.tag == "emitter":
            _scale_emitter(el, scale, move)
    return ET.tostring(root, encoding="unicode")


def _scale_transform(el, scale: float, move: tuple, conjugate: bool = False):
    """Append a uniform scale, then the move, to ``el``'s to_world (made when absent); ``conjugate``:
    the scale's inverse first too, so a frame (camera, light) moves without being scaled."""
    t = next((c for c in el.findall("transform") if c.get("name") == "to_world"), None)
    if t is None:
        t = ET.SubElement(el, "transform", {"name": "to_world"})
    if conjugate:
        t.insert(0, ET.Element("scale", {"value": repr(1.0 / scale)}))
    ET.SubElement(t, "scale", {"value": repr(scale)})
    if any(move):
        ET.SubElement(t, "translate", {"value": " ".join(repr(c) for c in move)})


def _scale_clips(el, scale: float):
    """A sensor's near and far clip distances times ``scale``."""
    for name, default in SENSOR_CLIPS.items():
        f = next((c for c in el.findall("float") if c.get("name") == name), None)
        if f is None:
            f = ET.SubElement(el, "float", {"name": name, "value": repr(default)})
        f.set("value", repr(float(f.get("value")) * scale))


def _scale_emitter(el, scale: float, move: tuple):
    """A point light's position (or any emitter's to_world) scaled and moved; directions and environments kept."""
    kind = el.get("type")
    if kind in ("directional", "constant", "envmap", "sunsky", "sky", "sun"):
        return
    pos = next((c for c in el if c.get("name") == "position"), None)
    if pos is not None and all(k in pos.attrib for k in ("x", "y", "z")):
        for k, c in zip(("x", "y", "z"), move):
            pos.set(k, repr(float(pos.get(k)) * scale + c))
        return
    _scale_transform(el, scale, move, conjugate=True)
