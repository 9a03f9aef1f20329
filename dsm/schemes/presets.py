"""Engine presets: each engine's default bias as :mod:`combined` parameters per light type.

A preset names an engine; :func:`preset_for_light` turns a preset's ``SchemeSpec`` into the
:mod:`combined` instance with that engine's values for a directional, spot or point light. The
plan resolves every preset per light (a preset's spec before resolution carries the
directional values). Each value was read in the engine's own source (the files named in
``SOURCES``); a value that could not be verified is left out (``LEFT_OUT``) and its term is off.

Units (the kit's): world units; ``k texel``, k times the world width of one texel's footprint
at the receiver (constant over an orthographic map, growing with distance for spot and point
maps, so an engine's "normal bias times texel size times distance" is a plain texel count);
``k range``, a fraction of the view's depth range. On a single map the map's texel stands for
a cascade's texel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..core.types import Length, SchemeSpec, describe_params
from ..core.suggest import valid_words

LIGHT_TYPES = ("directional", "spot", "point")
SQRT2 = math.sqrt(2.0)


def _p(normal_offset=(0.0, "world"), depth_bias=(0.0, "world"), slope_scale=0.0, slope_clamp=None) -> dict:
    out = {"normal_offset": Length(*normal_offset), "depth_bias": Length(*depth_bias), "slope_scale": float(slope_scale)}
    if slope_clamp is not None:
        out["slope_clamp"] = Length(*slope_clamp)
    return out


@dataclass(frozen=True)
class Preset:
    """One engine's preset: its combined parameters per light type, the sources read, the unit mapping."""
    engine: str
    values: dict                    # light type -> combined parameters
    sources: tuple                  # (file, what was read there)
    mapping: str = ""               # how the engine's units became the kit's
    left_out: str = ""              # what could not be verified and is not encoded
    aliases: tuple = field(default=())


_BEVY_SRC = (
    ("bevyengine/bevy crates/bevy_light/src/directional_light.rs",
     "DEFAULT_SHADOW_DEPTH_BIAS = 0.02, DEFAULT_SHADOW_NORMAL_BIAS = 1.8"),
    ("bevyengine/bevy crates/bevy_light/src/spot_light.rs",
     "DEFAULT_SHADOW_DEPTH_BIAS = 0.02, DEFAULT_SHADOW_NORMAL_BIAS = 1.8"),
    ("bevyengine/bevy crates/bevy_light/src/point_light.rs",
     "DEFAULT_SHADOW_DEPTH_BIAS = 0.08, DEFAULT_SHADOW_NORMAL_BIAS = 0.6"),
    ("bevyengine/bevy crates/bevy_pbr/src/render/light.rs (extract_lights)",
     "normal bias * SQRT_2 ('worst-case diagonal offset'); point: * 2 / cube face size; spot: * 2 tan(outer) / size"),
    ("bevyengine/bevy crates/bevy_pbr/src/render/shadows.wgsl",
     "directional: normal_bias * cascade.texel_size * n + depth_bias * direction_to_light; point/spot: normal term * "
     "distance_to_light, depth_bias * unit vector to the light"),
    ("bevyengine/bevy crates/bevy_light/src/cascade.rs", "cascade_texel_size = cascade_diameter / texture size"),
)

PRESETS = {
    "bevy": Preset(
        "Bevy",
        {"directional": _p((1.8 * SQRT2, "texel"), (0.02, "world")),
         "spot": _p((1.8 * SQRT2, "texel"), (0.02, "world")),
         "point": _p((0.6 * SQRT2, "texel"), (0.08, "world"))},
        _BEVY_SRC,
        "depth bias: world units toward the light (= a world depth bias); normal bias: texels times sqrt(2); for spot "
        "and point lights Bevy multiplies the texel size at distance 1 by the distance, which is the kit's texel"),
    "godot": Preset(
        "Godot 4",
        {"directional": _p((2.0, "texel")), "spot": _p(), "point": _p()},
        (("godotengine/godot scene/3d/light_3d.cpp (commit 8ea4ec95)",
          "Light3D(): PARAM_SHADOW_BIAS 0.1, PARAM_SHADOW_NORMAL_BIAS 1.0; DirectionalLight3D(): normal bias 2.0; "
          "SpotLight3D(): bias 0.03; OmniLight3D(): the Light3D values"),
         ("godotengine/godot servers/rendering/renderer_rd/storage_rd/light_storage.cpp",
          "directional: shadow_normal_bias[j] = normal bias * split shadow_texel_size; shadow_bias[j] = bias / 100 * "
          "bias_scale; spot/omni: normal bias * shadow_texel_size * 10, spot bias / 100, omni bias as is"),
         ("godotengine/godot servers/rendering/renderer_rd/shaders/scene_forward_lights_inc.glsl",
          "spot: normal_bias = n * light_length * shadow_normal_bias * (1 - |n.l|); splane.z += shadow_bias / "
          "(light_length * inv_radius)")),
        "directional normal bias: texels of the split (the (1 - n.l) factor Godot's shader may apply is not modelled)",
        "the directional depth bias (bias / 100 times a per-split bias_scale computed in renderer_scene_cull.cpp, not "
        "verified); spot and omni biases (their shadow_texel_size and the depth units of their test not verified): "
        "spot and point resolve to no bias"),
    "unity_urp": Preset(
        "Unity URP",
        {"directional": _p((1.0, "texel"), (1.0, "texel")),
         "spot": _p((1.0, "texel"), (1.0, "texel")),
         "point": _p((0.0, "texel"), (1.0, "texel"))},
        (("Unity-Technologies/Graphics com.unity.render-pipelines.universal/Runtime/Data/UniversalRenderPipelineAsset.cs",
          "m_ShadowDepthBias = 1.0f, m_ShadowNormalBias = 1.0f, soft shadows off"),
         ("Unity-Technologies/Graphics com.unity.render-pipelines.universal/Runtime/ShadowUtils.cs (GetShadowBias)",
          "texelSize = frustumSize / shadowResolution; depthBias = -bias.x * texelSize; normalBias = -bias.y * "
          "texelSize; point lights: normalBias = 0"),
         ("Unity-Technologies/Graphics com.unity.render-pipelines.universal/ShaderLibrary/Shadows.hlsl (ApplyShadowBias)",
          "caster moved by lightDirection * depthBias and along its normal by (1 - n.l) * normalBias")),
        "multiples of the world texel size; URP applies both at the caster, the kit at the receiver (same depth "
        "offset; the normal term as a receiver normal offset without URP's (1 - n.l) factor); for spot and point "
        "lights URP computes one texel size from the light's range, the kit's texel is the one at each receiver"),
    "unity_hdrp": Preset(
        "Unity HDRP",
        {t: _p((0.75 * SQRT2, "texel"), slope_scale=2.5) for t in LIGHT_TYPES},
        (("Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/Runtime/Lighting/Light/"
          "HDAdditionalLightData.cs", "m_NormalBias = 0.75f, m_SlopeBias = 0.5f; worldTexelSize = 2 / m00 / viewport "
          "width * sqrt(2); baseBias = 5 (raised only for high-quality soft shadows); slopeBias = "
          "HDShadowUtils.GetSlopeBias(baseBias, m_SlopeBias) = 5 * 0.5"),
         ("Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/Runtime/Lighting/Shadow/"
          "HDShadowUtils.cs", "GetSlopeBias(baseBias, normalizedSlopeBias) = normalizedSlopeBias * baseBias"),
         ("Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/Runtime/Lighting/Shadow/"
          "HDShadowManager.cs", "cmd.SetGlobalDepthBias(1.0f, shadowRequest.slopeBias)"),
         ("Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/Runtime/Lighting/Shadow/"
          "HDShadowAlgorithms.hlsl", "EvalShadow_NormalBias: normalWS * normalBias * worldTexelSize (times the "
          "distance for perspective maps)")),
        "normal bias: 0.75 * sqrt(2) texels at the receiver; slope bias: the rasterizer's slope factor 2.5 on m",
        "the rasterizer's constant depth bias of 1 unit (its size depends on the atlas depth format, not verified; "
        "below 2^-16 of the range)"),
    "filament": Preset(
        "Filament",
        {t: _p((0.5, "texel"), (0.001, "world"), slope_scale=2.0) for t in LIGHT_TYPES},
        (("google/filament filament/include/filament/LightManager.h (ShadowOptions)",
          "constantBias = 0.001f (world units, 'shadows are moved away from the light'), normalBias = 1.0f, "
          "polygonOffsetConstant = 0.5f, polygonOffsetSlope = 2.0f"),
         ("google/filament filament/src/ShadowMapManager.cpp",
          "'we need a half-texel size, so we multiply by 0.5': shadowBias = 0.5 * normalBias * world texel size"),
         ("google/filament shaders/src/shadowing.fs (computeLightSpacePosition)", "p += n * (sinTheta * b)")),
        "constant bias: world; normal bias: half a texel per unit (Filament's sin(theta) factor on it is not "
        "modelled: the kit offsets by the full amount); polygon offset slope: a factor on m",
        "polygonOffsetConstant 0.5 (depth-resolution units of the map's format: cannot be added to a world bias; "
        "below 2^-16 of the range); the spot and point lights' normal-bias scaling (not reopened: the "
        "directional value is used)"),
    "three": Preset(
        "three.js",
        {t: _p() for t in LIGHT_TYPES},
        (("mrdoob/three.js src/lights/LightShadow.js", "this.bias = 0; this.normalBias = 0"),),
        "no bias"),
    "mjp_shadows": Preset(
        "TheRealMJP Shadows",
        {t: _p(depth_bias=(0.005, "range")) for t in LIGHT_TYPES},
        (("TheRealMJP/Shadows Shadows/AppSettings.cs",
          "Bias = 0.005f, OffsetScale = 0.0f (normal offset), UsePlaneDepthBias = true"),
         ("TheRealMJP/Shadows Shadows/Mesh.hlsl", "lightDepth -= bias only without UsePlaneDepthBias_; with it, a "
          "receiver-plane depth bias and min(fractionalSamplingError, 0.01)")),
        "Bias compares in the cascade's [0, 1] depth: a fraction of the depth range; the sample has only a "
        "directional light, its values are used for spot and point. This is the sample's constant-bias path",
        "the sample's default path (UsePlaneDepthBias on), which does not apply Bias: a receiver-plane depth bias "
        "(measure it with the receiver_plane scheme)"),
    "metal_api": Preset(
        "Metal API call of Salcedo's shadow-map article",
        {t: _p(depth_bias=(2.0 ** -24, "range"), slope_scale=3.0, slope_clamp=(1.0 / 128.0, "range"))
         for t in LIGHT_TYPES},
        (("Salcedo's shadow-map article", "setDepthBias(1, slopeScale: 3, clamp: 1/128)"),),
        "1 unit of a 24-bit depth buffer = 2^-24 range; clamp 1/128 range (here on the slope term; the hardware "
        "clamps the sum, a difference of at most 2^-24 range)"),
}


def names() -> list:
    """The preset names, sorted."""
    return sorted(PRESETS)


def spec(name: str) -> SchemeSpec:
    """The preset's spec before resolution (it carries the directional values)."""
    from . import combined
    return SchemeSpec(combined.NAME, combined.Params(**PRESETS[name].values["directional"]), preset=name)


def preset_for_light(scheme_spec: SchemeSpec, light_type: str) -> SchemeSpec:
    """A preset's :mod:`combined` instance for one light type; any other spec as it is."""
    if scheme_spec.preset is None:
        return scheme_spec
    if light_type == "area":
        light_type = "spot"       # an area light's map is a perspective view from its centre, as engines cast it
    if light_type not in LIGHT_TYPES:
        raise ValueError(f"light type {light_type!r} has no preset values ({valid_words(light_type, LIGHT_TYPES)})")
    from . import combined
    return SchemeSpec(combined.NAME, combined.Params(**PRESETS[scheme_spec.preset].values[light_type]),
                      preset=scheme_spec.preset)


def text() -> list:
    """``dsm schemes`` lines: every preset's values per light type and its citations."""
    from . import combined
    lines = ["presets (each a combined instance per light type; a term not verified in the engine's source is off):"]
    for name in names():
        p = PRESETS[name]
        lines.append(f"  {name}  [{p.engine}]")
        for t in LIGHT_TYPES:
            lines.append(f"    {t:11s} {describe_params(combined.Params(**p.values[t]))}")
        for f, what in p.sources:
            lines.append(f"    source: {f}: {what}")
        if p.mapping:
            lines.append(f"    units: {p.mapping}")
        if p.left_out:
            lines.append(f"    left out (not verified): {p.left_out}")
    lines.append("  unreal: not encoded (Unreal Engine's source is not public; its r.Shadow.* defaults could not be "
                 "opened and verified)")
    return lines
