"""Cache policy ``none``: a map is rebuilt whenever its view or any caster moved (the reference).

What a cache saves is measured against it: its map is always this frame's. While nothing moves
and its view's signature holds, the map kept is the one a rebuild would cast, so it is kept
(motion's results before moving casters, bit for bit)."""

NAME = "none"
PARTIAL = False                 # a move of a caster re-casts no part of the map kept


def rebuild(view_changed: bool, geometry_changed: bool, age: int, period: int) -> bool:
    """Whether the frame's map is cast again (``age``, ``period``: unused)."""
    return view_changed or geometry_changed
