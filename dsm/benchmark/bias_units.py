"""Each engine preset's bias in world units and in texels at each scale of the suite.

A preset's term is given either in world units (constant as the scene grows, so it is wrong at
some scale) or in texels (it scales with the map, so it is scale-free); the conversion uses the
texel width in world units the run measured (metrics.csv's ``texel_size``; for cascades the
case's, as the kit reports it). A ``range`` term (a fraction of the depth range) is shown as given.
"""
from __future__ import annotations

from ..schemes.presets import PRESETS
from .ranking import at_origin

TERMS = ("depth_bias", "normal_offset")


def converted(length, texel_world: float) -> tuple:
    """(world units, texels) of a Length at a texel width ``texel_world``; None where not convertible."""
    if length.unit == "world":
        return length.value, length.value / texel_world if texel_world > 0 else None
    if length.unit == "texel":
        return length.value * texel_world, length.value
    return None, None


def bias_rows(doc: dict, scene: str) -> list:
    """Per preset, light and unit at ``scene`` (at the origin): each term's value as given, in world units and in texels."""
    out = []
    for r in doc["cases"]:
        if r["scene"] != scene or r["contender"] not in PRESETS or not at_origin(r):
            continue
        values = PRESETS[r["contender"]].values[r["light"]]
        row = {"preset": r["contender"], "light": r["light"], "unit": r["unit"], "texel_size": r["texel_size"],
               "error_rate": r["error_rate"]}
        for term in TERMS:
            length = values[term]
            row[term] = f"{length.value:g} {length.unit}"
            row[f"{term}_world"], row[f"{term}_texels"] = converted(length, r["texel_size"])
        out.append(row)
    return sorted(out, key=lambda x: (x["preset"], x["light"], x["unit"]))


def scale_free(name: str) -> bool:
    """Whether every nonzero term of preset ``name`` is in texels or depth range (both follow the scene's scale)."""
    return all(v[t].value == 0 or v[t].unit in ("texel", "range") for v in PRESETS[name].values.values() for t in TERMS)
