"""Cache policy ``stagger:N``: a map is cast every N frames, and whenever its view changes.

Engines' staggered updates re-derived: Unity's HDRP lets a light's shadow update "every frame",
"on enable" or "on demand", and its cascades and Godot's directional and positional shadows are
commonly refreshed on a frame budget, a map re-rendered every N frames in between its view's
changes. Between casts a moving caster leaves a ghost and a missing shadow up to N - 1 frames
old; ``stagger:1`` is ``none`` (a map cast every frame)."""

NAME = "stagger"
PARTIAL = False                 # a move of a caster re-casts no part of the map kept


def rebuild(view_changed: bool, geometry_changed: bool, age: int, period: int) -> bool:
    """Whether the frame's map is cast again (``age``: frames since the kept map was cast)."""
    return view_changed or age >= period
