"""What one map's cases share, and what one case is: plain values, built by whoever schedules them."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..core.suggest import valid_words
from ..core.types import MomentSpec

# what a context measures beyond the counts and rates every case has (each a group of columns):
#   seams     near/off a face seam (a cube or dual-paraboloid view)
#   split     errors split into the resolution's and the bias's (the per-texel oracle's ``wrong``)
#   attached  the attached-shadow receivers' V (backface_lit_rate) and the plane fallbacks
#   contact   the screen-space contact march after the lookup ([contact])
#   cascade   per cascade: counts, texels per pixel, the distance curve
#   leak      peter-panning split into the shadow's edge and leak deep inside it ([map] kind given)
MEASURES = frozenset({"seams", "split", "attached", "contact", "cascade", "leak"})


@dataclass(frozen=True)
class Case:
    """One case of a map: a scheme instance (or a pre-filtered instance), its filter and stored format,
    and the hybrid instance that sends some of its receivers to rays (dsm.hybrid), if any."""
    id: str           # "0001", ...: its place in the plan
    spec: object      # SchemeSpec, or MomentSpec (a pre-filtered instance)
    filter: str
    format: str
    hybrid: object = None     # HybridSpec ([hybrid]), or None: the map alone

    @property
    def prefiltered(self) -> bool:
        """Whether the case looks up a pre-filtered map's moments (not a depth map)."""
        return isinstance(self.spec, MomentSpec)

    @property
    def lookup_key(self) -> tuple:
        """(spec, filter, format): how a map's lookup wavefront names the case."""
        return self.spec, self.filter, self.format


@dataclass(frozen=True)
class Where:
    """A map's place in the plan, as each of its cases' rows names it."""
    scene: str
    light: str
    view: str
    resolution: int
    total_texels: int
    culling: str
    cascade_layout: str = ""


@dataclass
class MapContext:
    """What every case of one map shares: the scene's data and G-buffer, the light set-up (the
    receivers inside the view, their exact V*), the view, the map (as built and per stored
    format), the receivers per stored format, and what its cases measure."""
    where: Where
    scene: object                 # dsm.scenes.data.SceneData
    gbuffer: object               # dsm.scenes.gbuffer.GBuffer: the camera's pixels
    setup: object                 # dsm.pipeline.LightSetup, inside the view
    view: object
    depth_map: object             # the map as built (float32): a pre-filtered instance's moments are made of it
    stored: dict                  # format -> the map as that format stores it
    receivers: dict               # format -> Receiver in that format's depth function, None without receivers
    seed: int
    repeats: int                  # timed repeats of a lookup
    measures: frozenset = frozenset()
    backfacing: dict = field(default_factory=dict)   # format -> attached-shadow Receiver, or None
    seam_texels: np.ndarray | None = None            # texels to a face seam per receiver
    wrong: dict = field(default_factory=dict)        # format -> wrong under the per-texel oracle, or None
    leak_texels: float = float("nan")                # [map] leak_texels: an edge within, leak deeper inside
    deep: dict = field(default_factory=dict)         # format -> deep in the exact shadow per receiver (made once)
    moments: Callable | None = None   # (MomentSpec, format) -> (MomentMap, its build Timing or None)
    march: Callable | None = None     # Receiver -> (occluded per receiver, the march's Timing)

    def __post_init__(self):
        unknown = set(self.measures) - MEASURES
        if unknown:
            raise ValueError(f"MapContext: unknown measures {sorted(unknown)} "
                             f"({valid_words(sorted(unknown)[0], sorted(MEASURES))})")

    @property
    def image_size(self) -> tuple:
        """(width, height) of the camera's image."""
        return self.gbuffer.width, self.gbuffer.height
