"""The map's float32 headroom: how many float32 steps a texel spans where the receivers sit.

The kit simulates an engine that holds positions in float32 (``precision = "world"``: world
coordinates; ``"camera_relative"``: relative to the camera). Far from that frame's origin a
float32 step grows (0.0625 at 1e6) while a texel does not, so the map's depths and lookup
positions round to a few steps per texel, and acne and peter-panning include that rounding.
That is a legitimate effect of the engine being simulated (the exact side stays exact:
:mod:`dsm.scenes.exact_frame`), and a user must be told it is there:

- ``f32_step``: the float32 spacing at the receivers' largest coordinate, in the frame the
  map is built in (world units);
- ``texel_f32_steps``: the receivers' median texel width over that step.

Below :data:`FEW_STEPS` steps per texel a case is *precision-limited*: run.json lists such
cases, table.md and the run's last lines say so.
"""
from __future__ import annotations

import math

import numpy as np

FEW_STEPS = 64.0      # a texel spanning fewer float32 steps than this rounds visibly (a 1/64-texel bias)
UNDEFINED = math.nan


def headroom(max_abs_coordinate: float, texel_world: float) -> dict:
    """``f32_step`` and ``texel_f32_steps`` of receivers whose largest absolute coordinate in the
    map's frame is ``max_abs_coordinate``, with median texel width ``texel_world`` (NaN without
    receivers)."""
    if not (math.isfinite(max_abs_coordinate) and math.isfinite(texel_world)):
        return {"f32_step": UNDEFINED, "texel_f32_steps": UNDEFINED}
    step = float(np.spacing(np.float32(max_abs_coordinate)))
    return {"f32_step": step, "texel_f32_steps": texel_world / step}


def limited(rows: list) -> list:
    """The rows whose texel spans fewer than FEW_STEPS float32 steps."""
    out = []
    for r in rows:
        steps = r.get("texel_f32_steps")
        if isinstance(steps, (int, float)) and math.isfinite(steps) and steps < FEW_STEPS:
            out.append(r)
    return out


def summary(rows: list) -> str:
    """One line on the precision-limited cases, or "" where there are none."""
    few = limited(rows)
    if not few:
        return ""
    worst = min(few, key=lambda r: r["texel_f32_steps"])
    # a scene's label names its non-default parameters (dsm.scenes): already relative to its camera
    relative = all("precision=camera_relative" in str(r.get("scene", "")) for r in few)
    fix = ("they are rendered relative to a camera far from their receivers: a camera nearer to them holds more"
           if relative else "[[scene]] precision = \"camera_relative\" shows what rendering relative to the camera "
           "buys back")
    return (f"{len(few)} cases have a texel spanning fewer than {FEW_STEPS:g} float32 steps at the receivers "
            f"(fewest {worst['texel_f32_steps']:.3g}, scene {worst['scene']}: a step there is "
            f"{worst['f32_step']:.3g}): their acne and peter-panning include the map's float32 rounding; {fix}")
