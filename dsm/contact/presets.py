"""Engines' contact-shadow settings as ``[contact] preset = "..."``, each read in the engine's source.

Only values read in a source file are encoded; an engine whose settings do not map onto the
march's four parameters (length, steps, thickness, jitter) with certainty is listed as not
encoded, with the reason (``dsm schemes`` prints both).
"""
from __future__ import annotations

from ..types import ContactSpec, Length

PRESETS = {
    "bevy": (ContactSpec(Length(0.3, "world"), 16, Length(0.1, "world"), 0.0), "Bevy", [
        "bevyengine/bevy crates/bevy_pbr/src/contact_shadows.rs (commit 063a1251): ContactShadows::default() = "
        "linear_steps 16, thickness 0.1, length 0.3 (\"the length of the contact shadow ray in world space\"; the "
        "thickness: \"depth buffer fragments are cuboids with a constant thickness\")"],
        "units: Bevy's metres as world units; jitter 0 (the shader's per-pixel noise and refinement steps not "
        "read, not encoded)"),
}

NOT_ENCODED = {
    "hdrp": "Unity HDRP (com.unity.render-pipelines.high-definition/Runtime/Lighting/Shadow/ContactShadows.cs: "
            "length 0.15 m, sampleCount 8, thicknessScale 0.15, rayBias 0.2, distanceScaleFactor 0.5): the length "
            "is rescaled by the depth at the ray's origin and the thickness is a scale whose world meaning is in "
            "the shader, not read; not encoded",
    "unreal": "Unreal Engine (contact shadows per light; r.Shadow.Virtual.ScreenRayLength): its source is not "
              "public here and the screen-space length's units were not verified; not encoded",
}


def text() -> list:
    """``dsm schemes``' lines for the contact presets: the encoded ones with their sources, then the others."""
    lines = ["contact shadows ([contact] preset = \"...\", or length, steps, thickness, jitter; after every "
             "scheme, light and filter):"]
    for name, (spec, engine, sources, note) in PRESETS.items():
        lines.append(f"  {name}  [{engine}]  length={spec.length} steps={spec.steps} thickness={spec.thickness} "
                     f"jitter={spec.jitter:g}")
        lines += [f"    source: {s}" for s in sources] + [f"    {note}"]
    lines += [f"  {name}: {why}" for name, why in NOT_ENCODED.items()]
    return lines
