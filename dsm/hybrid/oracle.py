"""The floor: rays exactly where the map is wrong (it reads V*, so it is measured, never shipped).

With ``budget`` below 1 it traces the first ``floor(budget * receivers)`` wrong receivers in the
receivers' order: the least error any rule can leave with that many rays, the budget curve's floor.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .base import Inputs, Selection

NAME = "oracle"
SOURCE = "the floor: the fewest rays that make the case exact (reads V*)"


@dataclass(frozen=True)
class Params:
    """The oracle's ray budget."""
    budget: float = field(default=1.0, metadata={"doc": "oracle: rays at most, per receiver (1: every wrong "
                                                        "receiver)", "min": 0.0, "max": 1.0})


def select(inputs: Inputs, params) -> Selection:
    """The map's wrong receivers (lit >= 0.5 against V*), at most ``budget`` rays per receiver."""
    wrong = (inputs.v_map >= 0.5) != inputs.v_star
    cap = int(np.floor(params.budget * inputs.n))
    keep = np.flatnonzero(wrong)[:cap]
    trace = np.zeros(inputs.n, bool)
    trace[keep] = True
    return Selection(trace)
