"""Cache policy ``static``: a map is cast when its view changes and kept however its casters move.

Engines' cached shadow maps for casters flagged static: UE5's virtual shadow maps document for a
primitive whose shadow cache invalidation is ``Static`` that "if the primitive is actually moved,
the result is undefined"; Unity's and Godot's cached or on-demand maps are rebuilt when the light
or its projection changes or when asked. A caster that moves leaves its shadow where it was
(a ghost) and casts none where it is (missing)."""

NAME = "static"
PARTIAL = False                 # a move of a caster re-casts no part of the map kept


def rebuild(view_changed: bool, geometry_changed: bool, age: int, period: int) -> bool:
    """Whether the frame's map is cast again (``age``, ``period``: unused)."""
    return view_changed
