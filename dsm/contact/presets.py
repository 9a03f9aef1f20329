"""Engines' contact-shadow settings as ``[contact] preset = "..."``, each read in the engine's source.

Only values read in a source file are encoded; an engine whose settings do not map onto the
march's parameters (length, steps, thickness, jitter, and the depth-scaled length and thickness of
HDRP's) with certainty is listed as not encoded, with the reason (``dsm schemes`` prints both). What
a preset's engine does that the march does not is named in its note.
"""
from __future__ import annotations

from ..core.types import ContactSpec, Length

HDRP = "Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/Runtime"
# HDRP's depth-compare threshold is ``thicknessScale * 10`` (the C# side) times ``max(0.07, 1 / sampleCount)``
# of the NDC-depth change over one ray length, and its test ``|thr - diff| < thr`` accepts ``0 < diff < 2 thr``
HDRP_THICKNESS_PER_LENGTH = 2 * (0.15 * 10) * max(0.07, 1 / 8)

PRESETS = {
    "bevy": (ContactSpec(Length(0.3, "world"), 16, Length(0.1, "world"), 0.0), "Bevy", [
        "bevyengine/bevy crates/bevy_pbr/src/contact_shadows.rs (commit 063a1251): ContactShadows::default() = "
        "linear_steps 16, thickness 0.1, length 0.3 (\"the length of the contact shadow ray in world space\"; the "
        "thickness: \"depth buffer fragments are cuboids with a constant thickness\")"],
        "units: Bevy's metres as world units; jitter 0 (the shader's per-pixel noise and refinement steps not "
        "read, not encoded)"),
    "hdrp": (ContactSpec(Length(0.15, "world"), 8, Length(0.0, "world"), 0.0, length_depth_scale=0.5,
                         length_depth_min=0.5, thickness_per_length=HDRP_THICKNESS_PER_LENGTH), "Unity HDRP", [
        f"{HDRP}/Lighting/Shadow/ContactShadows.cs (commit 053fa9a1): the volume's defaults length 0.15 (metres), "
        "distanceScaleFactor 0.5, sampleCount 8, thicknessScale 0.15, rayBias 0.2, maxDistance 50, fadeDistance 5, "
        "minDistance 0, fadeInDistance 0, opacity 1",
        f"{HDRP}/RenderPipeline/HDRenderPipeline.LightLoop.cs (commit 02a1e8c6): the shader gets length, "
        "distanceScaleFactor, thicknessScale x 10, rayBias x 0.01",
        f"{HDRP}/Lighting/Shadow/ContactShadows.compute (commit 0a82c9d4): ray length = length x max(0.5, "
        "linearDepth x distanceScaleFactor); threshold = |NDC depth change over one ray length along the view axis| "
        "x thickness x max(0.07, 1/sampleCount), occluded where 0 < buffer - sample < 2 x threshold (reversed z); "
        "directional, point and spot lights"],
        "units: HDRP's metres as world units; the depth scaling is exact; the thickness is HDRP's threshold to "
        "first order (HDRP's is in NDC depth, 1/z: equal to 0.375 x the ray length in view depth as the length "
        "over the view depth goes to 0). Not simulated: samples evenly spaced in NDC (here in world), the "
        "per-pixel dither of +-0.5 step (here jitter 0), the ray bias (the start moved 0.2% of its camera distance "
        "toward the camera, HDRP's positions being camera-relative), the half-resolution first pass, the "
        "screen-edge and distance fades (a binary shadow here; the distance fade is 1 nearer than 45 m); "
        "applied to every light here, area lights included"),
}

NOT_ENCODED = {
    "unreal": "Unreal Engine: its source is not public here. The documented light property Contact Shadow Length "
              "is a screen-space length unless bContactShadowLengthInWS (dev.epicgames.com/documentation/"
              "unreal-engine/API/Runtime/Engine/FLightSceneProxy/bContactShadowLengthInWS, 5.4; docs.unrealengine."
              "com/4.26/en-US/BuildingWorlds/LightingAndShadows/ContactShadows, which uses 0.1 as an example); "
              "what the screen-space unit is a fraction of, the step count and the thickness are not documented "
              "there; not encoded",
}


def text() -> list:
    """``dsm schemes``' lines for the contact presets: the encoded ones with their sources, then the others."""
    lines = ["contact shadows ([contact] preset = \"...\", or length, steps, thickness, jitter, "
             "length_depth_scale, length_depth_min, thickness_per_length; after every scheme, light and filter):"]
    for name, (spec, engine, sources, note) in PRESETS.items():
        lines.append(f"  {name}  [{engine}]  {describe(spec)}")
        lines += [f"    source: {s}" for s in sources] + [f"    {note}"]
    lines += [f"  {name}: {why}" for name, why in NOT_ENCODED.items()]
    return lines


def describe(spec: ContactSpec) -> str:
    """A contact spec's parameters as words, the depth-scaled ones only where they are on."""
    length = str(spec.length)
    if spec.length_depth_scale > 0:
        length += f" x max({spec.length_depth_min:g}, {spec.length_depth_scale:g} z_view)"
    thick = f"{spec.thickness_per_length:g} x length" if spec.thickness_per_length > 0 else str(spec.thickness)
    return f"length={length} steps={spec.steps} thickness={thick} jitter={spec.jitter:g}"
