"""Variance shadow maps (Donnelly & Lauritzen, "Variance Shadow Maps", I3D 2006).

Moments E[t], E[t^2] of the normalized depth. V is Chebyshev's one-sided upper bound on the
fraction of the filter region at or beyond the receiver, with the variance clamped below at
``min_variance`` (normalized depth squared), then the light-bleeding reduction of Lauritzen
(GPU Gems 3, chapter 8, "Summed-Area Variance Shadow Maps", 2007): V' = linstep(bleed,
bleed_high, V), which cuts the bound's tail below ``bleed`` (and, with ``bleed_high`` below 1,
saturates it above, as three.js's ramp from 0.3 to 0.95 does). With ``W = 1`` and ``bleed = 0`` a receiver
behind its texel's depth by g is lit exactly when g^2 <= min_variance: the unfiltered VSM is
a depth test with a constant bias of sqrt(min_variance) depth ranges.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .base import chebyshev, linstep

NAME = "vsm"
SOURCE = "Donnelly & Lauritzen 2006 (I3D); light-bleeding reduction: Lauritzen 2007 (GPU Gems 3, ch. 8)"
encode = decode = None      # stored as floats only (base.FLOAT_FORMATS)


@dataclass(frozen=True)
class Params:
    """VSM's minimum variance (normalized depth squared) and light-bleeding reduction ramp
    [bleed, bleed_high] of Chebyshev's bound."""
    # at most 0.25: no depth distribution on [0, 1] has a larger variance (and 1e39 made V NaN)
    min_variance: float = field(default=1e-4, metadata={"min": 0.0, "max": 0.25, "tune": ("log", 1e-10, 0.25)})
    bleed: float = field(default=0.0, metadata={"min": 0.0, "max": 0.999, "tune": ("linear", 0.0, 0.9)})
    bleed_high: float = field(default=1.0, metadata={"max": 1.0, "above": "bleed", "label": "if_set"})


def count(params) -> int:
    """Two moments: E[t], E[t^2]."""
    return 2


def moment_key(params) -> tuple:
    """The moments do not depend on VSM's parameters."""
    return ()


def log_max(params) -> None:
    """None: no exponential moment, nothing a format could overflow."""
    return None


def moments(t, params) -> list:
    """[t, t^2] per texel."""
    return [t, t * t]


def visibility(b, t, prm):
    """linstep(bleed, bleed_high, Chebyshev's bound) of the receiver's normalized depth ``t``."""
    return linstep(prm.bleed, prm.bleed_high, chebyshev(b[0], b[1], t, prm.min_variance))
