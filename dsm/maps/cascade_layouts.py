"""Engines' cascade layouts (``[map] cascades = "bevy"`` etc.), as read in the source files each entry names.

Each layout sets the count, the split bounds, the maximum distance, the blend band and
stabilization as the engine's defaults do; the map's resolution stays the config's. Bias
per cascade needs no layout: a ``k texel`` bias is in the receiver's own cascade's texels.
"""
from __future__ import annotations

from ..core.types import CascadeSpec

# name -> (CascadeSpec, source files, what was read, what is not modelled)
LAYOUTS = {
    "bevy": (CascadeSpec(count=4, near=0.1, max_distance=150.0,
                         bounds=tuple(10.0 * (150.0 / 10.0) ** (i / 3) for i in range(4)),
                         blend=0.2, blend_rule="distance", stabilize=True, fit="cascade", engine="bevy"),
             "bevyengine/bevy crates/bevy_light/src/cascade.rs, crates/bevy_pbr/src/render/shadows.wgsl",
             "4 cascades, minimum distance 0.1, maximum 150, first far bound 10, bounds spaced geometrically "
             "(10 * 15^(i/3)), overlap 0.2 of each far bound blended linearly, fixed diameter, centre snapped to texels",
             "Bevy's map size 2048 (the config's resolution is kept)"),
    "godot": (CascadeSpec(count=4, max_distance=100.0, fractions=(0.1, 0.2, 0.5, 1.0), blend=0.0, stabilize=True,
                          fit="cascade", engine="godot"),
              "godotengine/godot scene/3d/light_3d.cpp, servers/rendering/renderer_scene_cull.cpp",
              "4 splits at 0.1 / 0.2 / 0.5 of max distance 100, blend_splits off, bounding sphere snapped to texels",
              "fade start 0.8 and the pancake (20): the kit does not fade shadows out"),
    "filament": (CascadeSpec(count=1, fit="frustum", stabilize=False, engine="filament"),
                 "google/filament filament/include/filament/LightManager.h, filament/src/ShadowMap.cpp",
                 "1 cascade by default, stable off; the light's frustum fitted to the view volume",
                 "its practical split applies only with more cascades"),
    "mjp": (CascadeSpec(count=4, fractions=(0.05, 0.15, 0.5, 1.0), stabilize=False, fit="cascade", engine="mjp"),
            "TheRealMJP/Shadows Shadows/AppSettings.cs, Shadows/MeshRenderer.cpp",
            "splits 0.05 / 0.15 / 0.5 / 1.0, stabilize off, automatic depth bounds (max distance: the farthest "
            "receiver)", "SDSM's minimum depth (the near bound stays the camera's near clip)"),
    "three": (CascadeSpec(count=3, split="practical", lam=0.5, stabilize=True, fit="cascade", engine="three"),
              "mrdoob/three.js examples/jsm/csm/CSM.js",
              "3 cascades, practical lambda 0.5, texel snap with floor", "CSM.js's fade"),
    "unity": (CascadeSpec(count=1, max_distance=50.0, fit="cascade", stabilize=False, engine="unity"),
              "Unity URP UniversalRenderPipelineAsset.cs",
              "max distance 50, 1 cascade (split presets 0.25 / (0.1, 0.3) / (0.067, 0.2, 0.467) for more)",
              "stable fit not verified (off); border 0.2 fade"),
}
