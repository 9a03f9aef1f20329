"""Engine presets of the pre-filtered kinds: a named engine's defaults as a kind's parameters.

Only values read in the engine's own source files are encoded, each with its file. MJP's
"Shadows" sample (github.com/TheRealMJP/Shadows, MIT): ``Shadows/AppSettings.cs`` (commit
338290a5) holds the UI defaults and ``Shadows/Mesh.hlsl``, ``VSM.hlsl``, ``MSM.hlsl`` (commit
37b61461) how they are used:

- VSM: the lookup passes ``VSMBias * 0.01`` as Chebyshev's minimum variance and
  ``LightBleedingReduction`` as the bleed amount; the defaults are 0.01 and 0: min_variance 1e-4
  (of the map's [0, 1] depth, the kit's normalized depth on an orthographic map), bleed 0.
- EVSM: exponents ``PositiveExponent = 40``, ``NegativeExponent = 5`` (capped at 42 in fp32 and
  5.54 in fp16; the kit refuses an exponent the format cannot hold instead), depth warped at
  2 depth - 1, and a minimum variance per warp of (VSMBias * 0.01 * c * w)^2, w the warped
  depth: a standard deviation of 1e-4 in x = 2t - 1 times the warp's slope c w. The kit's
  min_variance (normalized depth squared) times (dw/dt)^2 = (2 c w)^2 equals it for
  min_variance = (1e-4 / 2)^2 = 2.5e-9. ``mjp`` is the four-component mode, ``mjp2`` the
  two-component one.
- MSM (Hamburger): depth bias ``MSMDepthBias * 0.001`` and moment bias ``MSMMomentBias *
  0.001`` with defaults 0 and 0.003: moment bias 3e-6, depth bias 0.

three.js (github.com/mrdoob/three.js, MIT), ``VSMShadowMap``:
``src/renderers/shaders/ShaderChunk/shadowmap_pars_fragment.glsl.js`` (commit 99e4d385),
``VSMShadow``: the map holds the mean and the standard deviation of the depth; the variance is
their square floored at 0 (min_variance 0), Chebyshev's bound is remapped by
``clamp((p - 0.3) / (0.95 - 0.3), 0, 1)`` ("0.3 reduces light bleed": bleed 0.3, bleed_high
0.95), and a receiver at or before the mean is lit. The kit's moments are E[t], E[t^2], the same
statistics. three.js's compared depth is the depth buffer's: linear on an orthographic
(directional) map, as the kit's normalized depth, but not on a perspective one, so on a spot
light the preset's values are three.js's and its depth warp is not.

Filament (github.com/google/filament, Apache-2.0), ``ShadowType::VSM``, which is EVSM:
``shaders/src/shadowing.fs`` (commit 6498cf5b) ``ShadowSample_VSM`` warps the depth as
w = exp(c (2t - 1)) (and, with ``elvsm``, -1/w, the negative warp of the same exponent), floors
each warp's variance at (vsmDepthScale w)^2 and applies ``reduceLightBleed`` = linstep(amount,
1, p); ``filament/src/ds/ColorPassDescriptorSet.cpp`` sets the exponent to 5.54 without
``highPrecision`` (42 with it) and vsmDepthScale = minVarianceScale * 0.01 * exponent;
``filament/include/filament/Options.h`` ``VsmShadowOptions``: minVarianceScale 0.5,
lightBleedReduction 0.15, highPrecision false (a 16-bit map: use ``format = "float16"``). As for
MJP, (0.005 c w)^2 = min_variance (2 c w)^2 gives min_variance = 0.0025^2 = 6.25e-6. ``filament``
is the default (two moments), ``filament_elvsm`` the light option ``elvsm`` (four).

ESM has no preset (none of these engines ships one).
"""
from __future__ import annotations

from . import evsm, msm, vsm

SOURCES = {
    "mjp": "TheRealMJP/Shadows Shadows/AppSettings.cs (338290a5): VSMBias, LightBleedingReduction, "
           "PositiveExponent, NegativeExponent, MSMDepthBias, MSMMomentBias; Shadows/Mesh.hlsl, VSM.hlsl, MSM.hlsl "
           "(37b61461): their use",
    "three": "mrdoob/three.js src/renderers/shaders/ShaderChunk/shadowmap_pars_fragment.glsl.js (99e4d385): VSMShadow",
    "filament": "google/filament shaders/src/shadowing.fs (6498cf5b): ShadowSample_VSM, evaluateShadowVSM; "
                "filament/src/ds/ColorPassDescriptorSet.cpp: prepareShadowVSM (exponent, vsmDepthScale); "
                "filament/include/filament/Options.h: VsmShadowOptions",
}
FILAMENT_EXPONENT = 5.54              # prepareShadowVSM's exponent without highPrecision
FILAMENT_MIN_VARIANCE = (0.5 * 0.01 / 2.0) ** 2      # (minVarianceScale 0.01 / 2)^2, see above

PRESETS = {
    "vsm": {"mjp": vsm.Params(min_variance=1e-4, bleed=0.0),
            "three": vsm.Params(min_variance=0.0, bleed=0.3, bleed_high=0.95)},
    "evsm": {"mjp": evsm.Params(positive=40.0, negative=5.0, moments=4, min_variance=2.5e-9, bleed=0.0),
             "mjp2": evsm.Params(positive=40.0, negative=5.0, moments=2, min_variance=2.5e-9, bleed=0.0),
             "filament": evsm.Params(positive=FILAMENT_EXPONENT, negative=FILAMENT_EXPONENT, moments=2,
                                     min_variance=FILAMENT_MIN_VARIANCE, bleed=0.15),
             "filament_elvsm": evsm.Params(positive=FILAMENT_EXPONENT, negative=FILAMENT_EXPONENT, moments=4,
                                           min_variance=FILAMENT_MIN_VARIANCE, bleed=0.15)},
    "msm": {"mjp": msm.Params(moment_bias=3e-6, depth_bias=0.0)},
}


def names(kind: str) -> tuple:
    """The preset names of a kind (none for esm)."""
    return tuple(sorted(PRESETS.get(kind, {})))


def text() -> list:
    """``dsm schemes``' lines for these presets."""
    lines = ["  pre-filtered presets ([map.<kind>] preset = ...):"]
    for kind, by_name in PRESETS.items():
        for name, p in by_name.items():
            lines.append(f"    {kind} {name}: " + " ".join(f"{k}={v}" for k, v in vars(p).items()))
    lines += [f"    source ({engine}): {where}" for engine, where in SOURCES.items()]
    lines.append("    no ESM preset (none of these engines ships one); Filament's VSM is EVSM (its presets are evsm's)")
    return lines
