"""What a hybrid rule reads (:class:`Inputs`) and answers (:class:`Selection`), and its contract (:class:`Rule`).

A rule says, per receiver of a case, whether the map's answer stands or a ray decides, and how
much of the ray a tracer may skip (an interval along it, world units from the receiver). It
never reads V* except the ``oracle`` rule, which is the floor and no technique.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass
class Inputs:
    """What a rule may read about one case: its receivers (in the case's stored format), the stored
    map, the map's V, the receivers' pixels in the camera image, and (``oracle`` only) V*."""
    rx: object                 # dsm.maps.receiver.Receiver
    smap: object               # the map as the case's format stores it
    v_map: np.ndarray          # the case's V per receiver, in [0, 1]
    v_star: np.ndarray         # exact visibility per receiver (bool)
    pixels: np.ndarray         # pixel index of each receiver (row-major, ``width`` a row)
    width: int                 # the camera image's width, pixels
    directional: bool          # a directional light: depths are distances along the ray (an interval applies)

    @property
    def n(self) -> int:
        """How many receivers."""
        return int(self.v_map.size)


@dataclass
class Selection:
    """A rule's answer: which receivers a ray decides, and per receiver the part of its ray that may
    hold an occluder, ``[t_min, t_max]`` world units from the receiver (None: the whole ray)."""
    trace: np.ndarray                    # bool per receiver
    t_min: np.ndarray | None = None      # float32 per receiver
    t_max: np.ndarray | None = None

    @property
    def rays(self) -> int:
        """How many rays the rule asks for."""
        return int(np.count_nonzero(self.trace))


@runtime_checkable
class Rule(Protocol):
    """A hybrid rule module: its name, source, frozen ``Params`` and ``select``."""
    NAME: str
    SOURCE: str
    Params: type

    def select(self, inputs: Inputs, params) -> Selection:
        """Which receivers a ray decides (and the part of each ray that may hold an occluder)."""
