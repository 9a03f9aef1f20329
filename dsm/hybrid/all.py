"""Every receiver traced: the budget's upper end (one ray a receiver, the map's answer unused)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Inputs, Selection

NAME = "all"
SOURCE = "the budget's upper end (every receiver a ray)"


@dataclass(frozen=True)
class Params:
    """No parameters."""


def select(inputs: Inputs, params) -> Selection:
    """Every receiver, the whole ray."""
    return Selection(np.ones(inputs.n, bool))
