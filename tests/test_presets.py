"""Engine presets: combined instances per light type, with the values read in the engines' sources."""
import math

import pytest

from dsm.core.types import ConfigError, Length

S2 = math.sqrt(2.0)
W, T, R = "world", "texel", "range"

# (normal_offset, depth_bias, slope_scale, slope_clamp) per preset and light type, as read in:
EXPECTED = {
    # bevyengine/bevy crates/bevy_light/src/{directional,spot,point}_light.rs: DEFAULT_SHADOW_DEPTH_BIAS 0.02 / 0.02 /
    # 0.08, DEFAULT_SHADOW_NORMAL_BIAS 1.8 / 1.8 / 0.6; crates/bevy_pbr/src/render/light.rs: normal bias * SQRT_2
    "bevy": {"directional": ((1.8 * S2, T), (0.02, W), 0.0, None),
             "spot": ((1.8 * S2, T), (0.02, W), 0.0, None),
             "point": ((0.6 * S2, T), (0.08, W), 0.0, None)},
    # godotengine/godot scene/3d/light_3d.cpp: DirectionalLight3D normal bias 2.0 (times the split's texel size in
    # servers/rendering/renderer_rd/storage_rd/light_storage.cpp); the depth biases and the positional lights' terms
    # are not verified and left out
    "godot": {"directional": ((2.0, T), (0.0, W), 0.0, None),
              "spot": ((0.0, W), (0.0, W), 0.0, None),
              "point": ((0.0, W), (0.0, W), 0.0, None)},
    # Unity-Technologies/Graphics com.unity.render-pipelines.universal/Runtime/Data/UniversalRenderPipelineAsset.cs:
    # m_ShadowDepthBias 1.0, m_ShadowNormalBias 1.0 (texels); Runtime/ShadowUtils.cs: point lights normalBias = 0
    "unity_urp": {"directional": ((1.0, T), (1.0, T), 0.0, None),
                  "spot": ((1.0, T), (1.0, T), 0.0, None),
                  "point": ((0.0, T), (1.0, T), 0.0, None)},
    # Unity-Technologies/Graphics com.unity.render-pipelines.high-definition/.../HDAdditionalLightData.cs:
    # m_NormalBias 0.75 times worldTexelSize (which carries sqrt(2)); slope: baseBias 5 * m_SlopeBias 0.5
    # (HDShadowUtils.GetSlopeBias), set with SetGlobalDepthBias(1, slopeBias) in HDShadowManager.cs
    "unity_hdrp": {t: ((0.75 * S2, T), (0.0, W), 2.5, None) for t in ("directional", "spot", "point")},
    # google/filament filament/include/filament/LightManager.h: constantBias 0.001, normalBias 1.0,
    # polygonOffsetSlope 2.0; filament/src/ShadowMapManager.cpp: 0.5 * normalBias * texel size
    "filament": {t: ((0.5, T), (0.001, W), 2.0, None) for t in ("directional", "spot", "point")},
    # mrdoob/three.js src/lights/LightShadow.js: bias 0, normalBias 0
    "three": {t: ((0.0, W), (0.0, W), 0.0, None) for t in ("directional", "spot", "point")},
    # TheRealMJP/Shadows Shadows/AppSettings.cs: Bias 0.005 (in the cascade's [0, 1] depth), OffsetScale 0
    "mjp_shadows": {t: ((0.0, W), (0.005, R), 0.0, None) for t in ("directional", "spot", "point")},
    # Salcedo's shadow-map article: setDepthBias(1, slopeScale: 3, clamp: 1/128)
    "metal_api": {t: ((0.0, W), (2.0 ** -24, R), 3.0, (1.0 / 128.0, R)) for t in ("directional", "spot", "point")},
}


def test_every_preset_is_checked_here():
    from dsm.schemes import PRESETS
    assert sorted(PRESETS) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_preset_resolves_per_light_type_to_the_engines_values(name):
    from dsm.pipeline import scheme_spec
    from dsm.schemes import preset_for_light
    spec = scheme_spec({"preset": name})
    assert spec.preset == name and spec.name == "combined"
    for light_type, (offset, depth, slope, clamp) in EXPECTED[name].items():
        r = preset_for_light(spec, light_type)
        assert r.name == "combined" and r.preset == name
        p = r.params
        assert p.normal_offset.value == pytest.approx(offset[0], rel=1e-12)
        if offset[0]:
            assert p.normal_offset.unit == offset[1]
        assert p.depth_bias.value == pytest.approx(depth[0], rel=1e-12)
        if depth[0]:
            assert p.depth_bias.unit == depth[1]
        assert p.slope_scale == slope
        if clamp is None:
            assert math.isinf(p.slope_clamp.value)
        else:
            assert (p.slope_clamp.value, p.slope_clamp.unit) == clamp
        # the label says the resolved values
        assert r.label == (f"normal_offset={p.normal_offset} depth_bias={p.depth_bias} slope_scale={p.slope_scale} "
                           f"slope_clamp={p.slope_clamp}")
        assert preset_for_light(r, light_type) == r          # resolving twice changes nothing


def test_bevy_differs_per_light_type_and_plain_specs_pass_through():
    from dsm.pipeline import scheme_spec
    from dsm.schemes import preset_for_light
    bevy = scheme_spec({"preset": "bevy"})
    assert preset_for_light(bevy, "point").params != preset_for_light(bevy, "directional").params
    plain = scheme_spec({"name": "constant", "bias": "1 texel"})
    assert preset_for_light(plain, "point") is plain
    assert preset_for_light(bevy, "area") == preset_for_light(bevy, "spot")    # an area light's map is a spot's
    with pytest.raises(ValueError):
        preset_for_light(bevy, "laser")


def test_unknown_preset_is_one_line_listing_the_choices():
    from dsm.config.read import parse
    from dsm.schemes import PRESETS
    cfg = {"scene": [{"builtin": "plane"}], "scheme": [{"preset": "unreal_engine"}]}
    with pytest.raises(ConfigError) as e:
        parse(cfg, "x.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("x.toml: scheme[0].preset:")
    assert all(name in msg for name in PRESETS)


def test_combined_needs_slope_only_with_a_slope_term():
    from dsm.schemes import needs_of
    from dsm.pipeline import scheme_spec
    assert needs_of([scheme_spec({"name": "combined", "normal_offset": "1 texel", "depth_bias": 0.01})]) == set()
    assert needs_of([scheme_spec({"name": "combined", "slope_scale": 2.0})]) == {"slope"}
    assert needs_of([scheme_spec({"preset": "bevy"})]) == set()
    assert needs_of([scheme_spec({"preset": "metal_api"})]) == {"slope"}


def test_plan_resolves_presets_per_light():
    from dsm.config.read import parse
    from dsm.config import plan
    cfg = parse({"scene": [{"builtin": "plane_box"}],
                 "light": [{"type": "directional", "direction": [0.2, 0.1, -1.0]},
                           {"type": "point", "position": [0.5, -0.5, 3.0]}],
                 "map": {"resolution": 128, "view": "cube"}, "scheme": [{"preset": "bevy"}]}, "x.toml")
    p = plan.make(cfg)
    by_light = {m.light.split(":")[1]: m for m in p.maps}
    assert by_light["directional"].specs[0].params.normal_offset == Length(1.8 * S2, "texel")
    assert by_light["point"].specs[0].params.normal_offset == Length(0.6 * S2, "texel")
    assert by_light["point"].specs[0].params.depth_bias == Length(0.08, "world")
    assert all(m.needs == () for m in p.maps)             # no slope layer for Bevy's preset


def test_schemes_text_lists_every_preset_per_light_type_with_sources():
    from dsm.cli import schemes_text
    from dsm.schemes import PRESETS
    text = schemes_text()
    assert "combined  [" in text
    for name in PRESETS:
        assert f"\n  {name}  [" in text
    assert text.count("    source: ") >= len(PRESETS)
    assert "crates/bevy_light/src/point_light.rs" in text and "normal_offset=0.848528 texel depth_bias=0.08" in text
    assert "unreal: not encoded" in text


@pytest.mark.slow
def test_every_preset_runs_on_every_light_type(run_dict):
    from dsm.schemes import PRESETS
    cfg = {"experiment": {"name": "presets"}, "camera": {"resolution": [64, 64]},
           "scene": [{"builtin": "plane_box"}],
           "light": [{"type": "directional", "direction": [0.2, 0.1, -1.0]},
                     {"type": "spot", "position": [-2.0, 2.5, 5.0], "target": [0.0, 0.0, 0.0], "cutoff": 40},
                     {"type": "point", "position": [0.5, -0.5, 3.0], "direction": [0.0, 0.0, -1.0]}],
           "map": {"resolution": 128, "view": "cube"}, "timing": {"repeats": 1},
           "scheme": [{"preset": name} for name in sorted(PRESETS)]}
    res = run_dict(cfg)
    failed = [s for s in res.run["status"] if s.get("status") == "failed"]
    assert not failed, failed
    assert len(res.rows) == 3 * len(PRESETS)
    for r in res.rows:
        assert r["scheme"] == "combined" and r["preset"] in PRESETS and r["n_receivers"] > 0
    # the point light's Bevy row carries the point values, the directional one the directional values
    bevy = {r["light"].split(":")[1]: r["params"] for r in res.where(preset="bevy").rows}
    assert "normal_offset=0.848528 texel depth_bias=0.08" in bevy["point"]
    assert "normal_offset=2.54558 texel depth_bias=0.02" in bevy["directional"]
