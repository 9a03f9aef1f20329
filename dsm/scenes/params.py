"""The parameters of a [[scene]]: where it sits (scale, translate, precision) and each built-in's own."""
from __future__ import annotations

from dataclasses import dataclass, field


ORIGIN = (0.0, 0.0, 0.0)


# How the simulated engine holds positions (the map's build and lookup): ``world``, float32 world
# coordinates (the geometry rounded at its offset); ``camera_relative``, positions relative to the
# camera, shifted in float64 before rounding (Unreal's large world coordinates, Unity HDRP's
# camera-relative rendering). The exact side is exact in both (dsm.scenes.exact_frame).
PRECISIONS = ("world", "camera_relative")


@dataclass(frozen=True)
class Placement:
    """Where a built-in scene (or a mesh file) sits: ``scale`` multiplies geometry, camera and the
    config's light positions; ``translate`` then moves all of them (far-from-origin cases)."""
    scale: float = field(default=1.0, metadata={"min": 1e-30, "doc": "multiplies geometry, camera and the config's light positions"})
    translate: tuple = field(default=ORIGIN, metadata={"doc": "world offset [x, y, z] after scale"})
    precision: str = field(default="world", metadata={"choices": PRECISIONS, "doc": "how the simulated engine holds positions: float32 world coordinates, or relative to the camera"})


@dataclass(frozen=True)
class PlaneParams(Placement):
    """One 4 x 4 plane tilted ``tilt`` degrees about a horizontal axis at ``azimuth`` degrees; light from above."""
    tilt: float = field(default=45.0, metadata={"min": 0.0, "doc": "the plane's tilt, degrees"})
    azimuth: float = field(default=0.0, metadata={"doc": "the tilt axis's direction, degrees"})


@dataclass(frozen=True)
class PlaneBoxParams(Placement):
    """A closed unit box resting on an 8 x 8 ground: contact shadows."""


@dataclass(frozen=True)
class LShapeParams(Placement):
    """Weiskopf & Ertl 2003, figure 5: a closed L-shaped solid above the ground, light from right above."""


@dataclass(frozen=True)
class FloatingPlateParams(Placement):
    """An open 1.5 x 1.5 plate ``gap`` above the ground: the bias/gap threshold of peter-panning."""
    gap: float = field(default=0.2, metadata={"min": 0.0, "doc": "the plate's height over the ground, world units"})


@dataclass(frozen=True)
class StackedPlatesParams(Placement):
    """Two open plates over the ground, a 0.75 x 1.5 one at ``high`` over half of a 1.5 x 1.5 one
    at ``low``: occluders at two depths, the classic light leak of variance shadow maps."""
    low: float = field(default=0.25, metadata={"min": 0.0, "doc": "the lower plate's height, world units"})
    high: float = field(default=2.0, metadata={"min": 0.0, "doc": "the upper plate's height, world units"})


@dataclass(frozen=True)
class GrazingParams(Placement):
    """The ground and a box lit ``angle`` degrees from the ground's normal (80 to 89: projective aliasing)."""
    angle: float = field(default=85.0, metadata={"min": 0.0, "doc": "the light's angle from the ground's normal, degrees"})


@dataclass(frozen=True)
class RoomParams(Placement):
    """Brabec et al. 2002, figure 3: a closed 6 x 6 x 3 room (walls facing in) with objects around a point light."""


@dataclass(frozen=True)
class DoubleTorusParams(Placement):
    """Weiskopf & Ertl 2003, figure 6: a closed genus-2 solid (a double torus, 6,400 triangles) tilted above the ground."""


@dataclass(frozen=True)
class LongGroundParams(Placement):
    """A 200 x 20 ground with posts (0.4 x 0.4 x 4) every 10 units along both sides, the camera near
    the ground at one end looking along it: perspective aliasing, the cascades' scene."""


@dataclass(frozen=True)
class TerrainParams(Placement):
    """A real terrain in metres (dsm.scenes.terrain): 30 x 32 km of the Jacksboro fault DEM, 236 to 1076 m
    high, 275,772 triangles (every ``stride``-th sample), the camera on a ridge above its
    south-west, a low sun: cascades and scale on geometry nobody here made."""
    stride: int = field(default=1, metadata={"min": 1, "doc": "keep every stride-th elevation sample"})


@dataclass(frozen=True)
class OccluderParams(Placement):
    """One occluder of side ``size`` whose lowest point is at ``height`` over a square ground: dsm grad's test bed."""
    size: float = field(default=0.5, metadata={"min": 1e-30, "doc": "the occluder's side (a mesh: its largest extent), world units"})
    height: float = field(default=0.5, metadata={"min": 0.0, "doc": "the occluder's lowest point over the ground, world units"})
    ground_half: float = field(default=4.0, metadata={"min": 1e-30, "doc": "the ground's half side, world units"})


@dataclass(frozen=True)
class OccluderPlateParams(OccluderParams):
    """A square plate of side ``size`` at ``height`` over the ground (dsm grad's plate: its shadow's closed forms)."""


@dataclass(frozen=True)
class OccluderBoxParams(OccluderParams):
    """A closed box, ``size`` x ``size`` x ``box_height``, its bottom at ``height`` over the ground."""
    box_height: float = field(default=0.5, metadata={"min": 1e-30, "doc": "the box's height, world units"})


@dataclass(frozen=True)
class OccluderMeshParams(OccluderParams):
    """A PLY or OBJ mesh (z up) scaled so its largest extent is ``size``, centred over the origin in x and y,
    its lowest point at ``height`` over the ground."""
    mesh: str = field(default="", metadata={"path": (".ply", ".obj"), "doc": "the mesh file, relative to the "
                                            "config file; empty: the kit's Stanford bunny (data/meshes/mitsuba_bunny.ply)"})


@dataclass(frozen=True)
class FileParams(Placement):
    """A scene file. Meshes (OBJ/PLY) get a ground under them, a default camera and light."""
    up: str = field(default="y", metadata={"choices": ("x", "y", "z"), "doc": "a mesh file's up axis"})
    ground: str = field(default="yes", metadata={"choices": ("yes", "no"), "doc": "a ground under a mesh file"})


BUILTINS = {
    "plane": PlaneParams,
    "plane_box": PlaneBoxParams,
    "l_shape": LShapeParams,
    "floating_plate": FloatingPlateParams,
    "stacked_plates": StackedPlatesParams,
    "grazing": GrazingParams,
    "room": RoomParams,
    "double_torus": DoubleTorusParams,
    "long_ground": LongGroundParams,
    "terrain": TerrainParams,
    "occluder_plate": OccluderPlateParams,
    "occluder_box": OccluderBoxParams,
    "occluder_mesh": OccluderMeshParams,
}


FILE_SUFFIXES = (".xml", ".obj", ".ply")
