"""Contact-shadow presets (dsm.contact.presets) and the march's depth-scaled options, against a
march derived by hand in numpy float64 and the values read in the engines' sources."""

import numpy as np
import pytest

import dsm
import dsm.pipeline as pl
from conftest import base_config
from dsm.cli import schemes_text
from dsm.contact import march as contact
from dsm.core import record
from dsm.maps.lookup import resolve
from dsm.core.types import ContactSpec, Length
from test_contact import CAM_O, GAP, H, L, W, camera_frame, first_hit, pixel_rays, sun_on_plate

# a base length that the depth scale makes 0.35 (the floor) to ~0.45 over the plate scene's receivers
BASE, STEPS, DEPTH_SCALE, DEPTH_MIN, THICK_PER_LENGTH = 0.1, 8, 0.5, 3.5, 0.25


def scaled_hand_march(p):
    """Per receiver (rows of p): (occluded, ambiguous, length) of the hand march whose length is
    BASE max(DEPTH_MIN, DEPTH_SCALE z_view) and whose thickness is THICK_PER_LENGTH of it; ambiguous:
    a sample within float32's reach of a pixel border or of a comparison's bound, a grazed plate edge."""
    f, left, up, tx, ty = camera_frame()
    d = pixel_rays()
    z_b, _, _ = first_hit(d)
    p_plate = CAM_O + ((GAP - CAM_O[2]) / d[:, 2])[:, None] * d
    edge = np.abs(np.abs(p_plate[:, :2]).max(1) - 0.75) < 1e-4
    z_view = (p - CAM_O) @ f
    length = BASE * np.maximum(DEPTH_MIN, DEPTH_SCALE * z_view)
    thick = THICK_PER_LENGTH * length
    occ, amb = np.zeros(len(p), bool), np.zeros(len(p), bool)
    near = lambda a: np.abs(a - np.round(a)) < 2e-4
    for k in range(1, STEPS + 1):
        q = p - L * (length * k / STEPS)[:, None] - CAM_O     # toward the sun: -L
        z = q @ f
        x = (0.5 - 0.5 * (q @ left) / (z * tx)) * W
        y = (0.5 - 0.5 * (q @ up) / (z * ty)) * H
        inside = (x >= 0) & (x < W) & (y >= 0) & (y < H)
        idx = np.clip(np.floor(y), 0, H - 1).astype(int) * W + np.clip(np.floor(x), 0, W - 1).astype(int)
        behind = z - z_b[idx]
        occ |= inside & (behind > 0) & (behind < thick)
        amb |= near(x) | near(y) | (inside & ((np.abs(behind) < 2e-5) | (np.abs(behind - thick) < 2e-5)
                                              | edge[idx]))
    amb |= np.abs(DEPTH_SCALE * z_view - DEPTH_MIN) < 1e-5    # the floor's switch
    return occ, amb, length


@pytest.fixture(scope="module")
def plate():
    """The floating plate at GAP under the sun (camera W x H) and its receivers of a 256 map's view."""
    sd, gb, setup, view = sun_on_plate(256)
    return gb, setup, pl.receivers(view, setup, sd.diagonal)


def test_depth_scaled_length_and_thickness_are_the_hand_march(plate):
    gb, setup, rx = plate
    spec = ContactSpec(Length(BASE, "world"), STEPS, Length(5.0, "world"), 0.0, length_depth_scale=DEPTH_SCALE,
                       length_depth_min=DEPTH_MIN, thickness_per_length=THICK_PER_LENGTH)
    db = contact.depth_buffer(gb)
    occ = contact.march(db, rx, spec).numpy().astype(bool)
    _, p_rx, on_plate = first_hit(pixel_rays()[setup.pixels])
    hand, amb, length = scaled_hand_march(p_rx)
    assert (length > BASE * DEPTH_MIN + 0.02).mean() > 0.2 and (length == BASE * DEPTH_MIN).mean() > 0.2
    assert amb.mean() < 0.01
    assert np.array_equal(occ[~amb], hand[~amb])
    assert (hand & ~on_plate & ~setup.v_star).sum() > 100    # the plate's shadow on the ground, found
    prm = resolve(spec, rx)
    got_len, got_thick = (a.numpy() for a in contact.march_extent(db, rx, spec, prm))
    assert np.allclose(got_len, length, rtol=1e-5) and np.allclose(got_thick, THICK_PER_LENGTH * length, rtol=1e-5)


def test_options_off_leave_the_march_as_it_was(plate):
    """A depth floor above every receiver's scaled depth is the plain march of the floor's length
    (x2: exact in float32)."""
    gb, setup, rx = plate
    db = contact.depth_buffer(gb)
    plain = ContactSpec(Length(0.3, "world"), STEPS, Length(0.08, "world"), 0.0)
    floored = ContactSpec(Length(0.15, "world"), STEPS, Length(0.08, "world"), 0.0, length_depth_scale=1e-3,
                          length_depth_min=2.0)
    a, b = (contact.march(db, rx, s).numpy().astype(bool) for s in (plain, floored))
    assert a.sum() > 100 and np.array_equal(a, b)


def test_hdrp_preset_is_its_source_values():
    """ContactShadows.cs's defaults: length 0.15, distanceScaleFactor 0.5, sampleCount 8, thicknessScale
    0.15 (x 10 on the C# side); the shader's max(0.5, depth x scale) and 2 x thickness x max(0.07, 1/8)."""
    cfg = dsm.parse_config(base_config(contact={"preset": "hdrp"}), "<t>")
    c = cfg.contact
    assert (c.length, c.steps, c.jitter) == (Length(0.15, "world"), 8, 0.0)
    assert (c.length_depth_scale, c.length_depth_min) == (0.5, 0.5)
    assert c.thickness_per_length == pytest.approx(0.375)


def test_schemes_lists_the_presets_with_their_files():
    text = schemes_text()
    hdrp = [ln for ln in text.splitlines() if ln.startswith("  hdrp")]
    assert hdrp and "max(0.5, 0.5 z_view)" in hdrp[0] and "steps=8" in hdrp[0]
    for path in ("Lighting/Shadow/ContactShadows.cs", "Lighting/Shadow/ContactShadows.compute",
                 "RenderPipeline/HDRenderPipeline.LightLoop.cs", "bevy_pbr/src/contact_shadows.rs"):
        assert path in text
    assert "  unreal: " in text and "not encoded" in text.split("  unreal: ")[1]


def test_hdrp_preset_runs_end_to_end(run_dict):
    cfg = base_config(scene=[{"builtin": "floating_plate", "gap": GAP}], camera={"resolution": [64, 48]},
                      scheme=[{"name": "constant", "bias": 0.3}], map={"resolution": 128},
                      light=[{"type": "directional", "direction": L.tolist()}], contact={"preset": "hdrp"},
                      report={"images": "none"})
    res = run_dict(cfg, "hdrp")
    (r,) = res.rows
    assert set(record.GROUPS["contact"]) <= set(r)
    assert r["n_peterpan"] > 0 and r["n_contact_recovered"] > 0
    assert r["n_contact_missed"] == r["n_peterpan"] - r["n_contact_recovered"]
    after = r["n_acne"] + r["n_contact_false"] + r["n_peterpan"] - r["n_contact_recovered"]
    assert r["contact_error_rate"] == pytest.approx(after / r["n_receivers"])


def test_depth_scaled_keys_parse_and_negative_values_are_config_errors():
    from dsm.core.types import ConfigError
    cfg = dsm.parse_config(base_config(contact={"length": 0.1, "length_depth_scale": 0.5, "length_depth_min": 2,
                                                "thickness_per_length": 0.3}), "<t>")
    assert (cfg.contact.length_depth_scale, cfg.contact.length_depth_min, cfg.contact.thickness_per_length) == \
        (0.5, 2.0, 0.3)
    for key in ("length_depth_scale", "length_depth_min", "thickness_per_length"):
        with pytest.raises(ConfigError) as e:
            dsm.parse_config(base_config(contact={key: -1}), "<t>")
        assert e.value.key == f"contact.{key}"
