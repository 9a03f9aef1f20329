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

Not encoded: three.js (``VSMShadowMap``) and Filament (VSM): their VSM source files could not
be opened here at a release that names its values; ESM has no preset (MJP's sample has none).
"""
from __future__ import annotations

from . import evsm, msm, vsm

SOURCES = ("TheRealMJP/Shadows Shadows/AppSettings.cs (338290a5): VSMBias, LightBleedingReduction, "
           "PositiveExponent, NegativeExponent, MSMDepthBias, MSMMomentBias; Shadows/Mesh.hlsl, VSM.hlsl, MSM.hlsl "
           "(37b61461): their use")

PRESETS = {
    "vsm": {"mjp": vsm.Params(min_variance=1e-4, bleed=0.0)},
    "evsm": {"mjp": evsm.Params(positive=40.0, negative=5.0, moments=4, min_variance=2.5e-9, bleed=0.0),
             "mjp2": evsm.Params(positive=40.0, negative=5.0, moments=2, min_variance=2.5e-9, bleed=0.0)},
    "msm": {"mjp": msm.Params(moment_bias=3e-6, depth_bias=0.0)},
}


def names(kind: str) -> tuple:
    """The preset names of a kind (none for esm)."""
    return tuple(sorted(PRESETS.get(kind, {})))


def text() -> list:
    """``dsm schemes``' lines for these presets."""
    lines = ["  pre-filtered presets ([map.<kind>] preset = ...; " + SOURCES + "):"]
    for kind, by_name in PRESETS.items():
        for name, p in by_name.items():
            lines.append(f"    {kind} {name}: " + " ".join(f"{k}={v}" for k, v in vars(p).items()))
    lines.append("    not encoded: three.js and Filament VSM (their source at a named release could not be read here); "
                 "no ESM preset")
    return lines
