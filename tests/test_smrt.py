"""Shadow-map ray tracing (dsm.maps.smrt): one ray to the light's centre with a fine march is the
nearest lookup (perspective, cube and virtual spot maps, every rule); with many rays the penumbra's
edges on the ground under a square plate and a square light are those of similar triangles (float64)
within a texel; a receiver's V does not depend on the other receivers; the presets and the refusals."""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from dsm import pipeline
from dsm.core.types import ConfigError, LightSpec
from dsm.maps import costs, smrt
from dsm.maps.receiver import Receiver
from dsm.scenes import geometry as scene_geometry

from conftest import base_config

# a square light (side A, height H) over a square plate (side B, height HS) over the ground
A, H, B, HS = 1.0, 4.0, 1.0, 2.0
BBOX = (np.array([-6.0, -6.0, 0.0]), np.array([6.0, 6.0, HS]))
LIGHT = LightSpec("area", position=(0.0, 0.0, H), direction=(0.0, 0.0, -1.0), shape="rectangle", size=(A,))


def _quad(z, half):
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    return scene_geometry.make_mesh("quad", v, np.array([[0, 1, 2], [0, 2, 3]]))


def _plate(variant, q, R=256, bias="1.5 texel"):
    """(spec of constant ``bias``, receivers at ground points q (n, 2), the plate's map of R^2)."""
    scene = mi.load_dict({"type": "scene", "ground": _quad(0.0, 6.0), "occluder": _quad(HS, B / 2)})
    view = pipeline.make_view(LIGHT, R, np.c_[q, np.zeros(len(q))], BBOX, "fitted")
    smap = pipeline.build_map(scene, view)
    p = mi.Point3f(mi.Float(q[:, 0]), mi.Float(q[:, 1]), mi.Float(np.zeros(len(q))))
    rx = Receiver.make(view, p, dr.zeros(mi.Vector3f, len(q)) + mi.Vector3f(0, 0, 1), 8.0)
    return pipeline.scheme_spec({"name": "constant", "bias": bias}), rx, smap


def _grid(g=90, half=2.5):
    xs = np.linspace(-half, half, g)
    X, Y = np.meshgrid(xs, xs)
    return np.stack([X.ravel(), Y.ravel()], 1)


@pytest.mark.parametrize("rule", ["hold", "eevee", "plain"])
def test_one_centre_ray_with_a_fine_march_is_the_nearest_lookup_on_a_perspective_map(variant, rule):
    """Every sample of the ray to the light's centre lies on the receiver's own texel ray: no sample
    occludes unless the receiver's own test fails (umbra, penumbra and lit receivers all present)."""
    spec, rx, smap = _plate(variant, _grid())
    near = pipeline.visibility(spec, rx, smap, "nearest")[0].numpy()
    got = pipeline.visibility(spec, rx, smap, f"smrt:1x64:{rule}")[0].numpy()
    assert 0.2 < near.mean() < 0.9
    assert np.array_equal(got, near)


@pytest.mark.parametrize("kind", ["cube", "virtual_spot"])
def test_one_ray_is_the_nearest_lookup_on_cube_and_virtual_maps(variant, kind):
    """A punctual light has no surface: SMRT's one ray goes to the map's origin, read on the receiver's
    own cube face or virtual level; V equals the nearest lookup's, receiver by receiver, for two schemes."""
    from dataclasses import replace
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.maps.virtual_punctual import VirtualSpotView
    from dsm.scenes.camera import Camera
    sd = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane_box"}), (64, 64))
    if kind == "cube":
        light = LightSpec("point", position=(0.6, -0.4, 2.0))
        setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), light, "p")
        view = pipeline.make_view(light, 256, pipeline.points_np(setup.p), sd.bbox, "cube")
    else:
        spot = {"position": (0.0, 2.5, 0.8), "target": (0.0, -0.5, 0.0), "cutoff": 40.0}
        setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), LightSpec("spot", **spot), "s")
        spec = replace(VIRTUAL_PRESETS["eevee_punctual"], resolution=2048, page_size=64)
        view = VirtualSpotView(spot["position"], np.subtract(spot["target"], spot["position"]), spot["cutoff"],
                               spec, Camera.from_sensor(sd.sensor), pipeline.points_np(setup.p), sd.bbox)
    specs = [pipeline.scheme_spec(s) for s in ({"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"})]
    smap = pipeline.build_map(sd.scene, view, pipeline.needs_of(specs))
    rx = pipeline.receivers(view, setup, sd.diagonal)
    for spec in specs:
        near = pipeline.visibility(spec, rx, smap, "nearest")[0].numpy()
        assert 0.0 < near.mean() < 1.0
        assert np.array_equal(pipeline.visibility(spec, rx, smap, "smrt:1x32")[0].numpy(), near)


def _edges(x, v):
    """(inner, outer) penumbra edge along x > 0: the first x with V > 0 and the last with V < 1."""
    return x[np.argmax(v > 0)], x[len(v) - 1 - np.argmax((v < 1)[::-1])]


@pytest.mark.slow
@pytest.mark.parametrize("rule", ["hold", "eevee"])
def test_many_rays_put_the_penumbra_edges_where_similar_triangles_do_within_a_texel(variant, rule):
    """Receivers on the line y = 0, x in [0, 2.5]: the plate's edge x = B/2 at height HS seen past the
    light's edges x = +-A/2 at height H puts the umbra's end at B/2 - (A/2 - B/2) HS / (H - HS) and the
    penumbra's at B/2 + (A/2 + B/2) HS / (H - HS) (float64); between them V is the lit strip of the
    light, linear in x. With 256 rays of 64 samples (bias 0.5 texel: no acne on the ground, a small
    step below the plate) SMRT's first partly lit and last partly shadowed receivers are within one
    texel of those edges; half the samples leave them farther (a ray passing just inside the plate's
    edge is missed between samples), and 4 rays have a larger mean error than 256."""
    x = np.linspace(0.0, 2.5, 1001)
    q = np.c_[x, np.zeros_like(x)]
    spec, rx, smap = _plate(variant, q, bias="0.5 texel")
    inner = B / 2 - (A / 2 - B / 2) * HS / (H - HS)
    outer = B / 2 + (A / 2 + B / 2) * HS / (H - HS)
    exact = np.clip((x - inner) / (outer - inner), 0.0, 1.0)
    texel = rx.texel_world.numpy()
    i_in, i_out = np.searchsorted(x, inner), np.searchsorted(x, outer)

    def edge_errors(filt):
        v = pipeline.visibility(spec, rx, smap, filt)[0].numpy()
        got_in, got_out = _edges(x, v)
        return abs(got_in - inner), abs(got_out - outer), np.abs(v - exact).mean()

    e_in, e_out, mae = edge_errors(f"smrt:256x64:{rule}")
    print(rule, "edge errors", e_in, e_out, "texel", texel[i_in], texel[i_out], "MAE", mae)
    assert e_in <= texel[i_in] and e_out <= texel[i_out]
    c_in, c_out, _ = edge_errors(f"smrt:256x32:{rule}")
    assert c_in + c_out > e_in + e_out
    assert edge_errors(f"smrt:4x64:{rule}")[2] > mae


def test_a_receivers_v_does_not_depend_on_the_other_receivers(variant):
    """The lattice's shift comes from the receiver's own position bits: every other receiver alone gives the same V."""
    q = _grid(40)
    spec, rx, smap = _plate(variant, q)
    full = pipeline.visibility(spec, rx, smap, "smrt:ue5_local")[0].numpy()
    _, rx2, _ = _plate(variant, q[::2])
    half = pipeline.visibility(spec, Receiver.make(smap.view, rx2.p_world, rx2.n_world, 8.0), smap,
                               "smrt:ue5_local")[0].numpy()
    assert 0.0 < full.mean() < 1.0 and np.array_equal(half, full[::2])


def test_presets_costs_and_labels():
    """The engines' defaults (docs/smrt.md names each source), taps = rays x samples, a custom label."""
    assert smrt.settings("smrt:ue5_local") == smrt.Settings(7, 8, "hold")
    assert smrt.settings("smrt:ue5_directional") == smrt.Settings(7, 8, "hold")
    assert smrt.settings("smrt:eevee") == smrt.Settings(1, 6, "eevee")
    assert smrt.settings("smrt:eevee_viewport") == smrt.Settings(16, 6, "eevee")
    assert smrt.settings("smrt:eevee_render") == smrt.Settings(64, 6, "eevee")
    assert smrt.settings("smrt") == smrt.settings("smrt:ue5_local")
    assert smrt.settings("smrt:16x4:plain") == smrt.Settings(16, 4, "plain")
    assert costs.filter_taps("smrt:ue5_local") == 56 and costs.filter_taps("smrt:eevee") == 6
    assert smrt.lattice(1) == [(0.5, 0.5)]
    assert smrt.march_times(4) == [0.5625, 0.25, 0.0625, 0.0]


@pytest.mark.parametrize("bad", ["smrt:ue6", "smrt:0x8", "smrt:4x8:sideways", "smrt:4x999"])
def test_bad_smrt_filters_are_refused_naming_the_key(bad):
    from dsm.config import read as config
    cfg = base_config(map={"resolution": 64, "filter": bad})
    with pytest.raises(ConfigError, match="map.filter") as err:
        config.parse(cfg)
    assert "ue5_local" in str(err.value) or "rays 1 to" in str(err.value)


def test_an_emitter_lights_rays_aim_at_its_triangles(tmp_path):
    """The Cornell box under its own luminaire (an XML emitter): the runner gives the view the emitter's
    surface, so 64 rays soften the shadow: their penumbra error against the reference is below a third
    of the nearest lookup's (a hard shadow), and below a third of one ray's (to one point of it)."""
    import dsm
    from conftest import MESHES
    cfg = base_config(camera={"resolution": [64, 64]}, scene=[{"file": str(MESHES / "cbox_mitsuba" / "cbox.xml")}],
                      light=[{"type": "area", "shape": "emitter", "max_samples": 1024}],
                      map={"resolution": 256, "filter": ["nearest", "smrt:1x16", "smrt:64x16"]},
                      scheme=[{"name": "constant", "bias": "1.5 texel"}])
    rows = {r["filter"]: r for r in dsm.run(cfg, out=tmp_path / "run", report=False).rows}
    assert int(rows["nearest"]["n_penumbra"]) > 50
    near, one = float(rows["nearest"]["mae_penumbra"]), float(rows["smrt:1x16"]["mae_penumbra"])
    soft = float(rows["smrt:64x16"]["mae_penumbra"])
    print("penumbra MAE: nearest", near, "1 ray", one, "64 rays", soft)
    assert soft < near / 3 and soft < one / 3
