"""Cache policy ``invalidate``: a map is cast whole when its view changes; when casters move, only
the texels whose rays meet a moving caster's bounds, where it was when the map's texels were cast
or where it is now, are cast again.

UE5's virtual shadow maps invalidate the cached pages a moving primitive's bounds touch, its
previous and its current bounds (Epic's documentation of shadow cache invalidation), and
re-render those pages alone. Here a texel is the unit (a map's texel is one ray through its
centre, so a texel whose ray meets neither bounds holds the same first hit, slope and second
depth as a fresh cast): the map kept is exact again after each frame, at the cost of the
re-cast texels (``recast_fraction``)."""

NAME = "invalidate"
PARTIAL = True


def rebuild(view_changed: bool, geometry_changed: bool, age: int, period: int) -> bool:
    """Whether the frame's map is cast again whole (a caster's move re-casts part of it instead)."""
    return view_changed
