"""Reference visibility against independent counts, and the spawn rule against Mitsuba's."""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from dsm import config, gbuffer, reference, scenes
from dsm.config import LightSpec

DATA = Path(__file__).parent / "data"


def _setup(spec_table, light, res=(160, 160)):
    spec = scenes.parse_scene(spec_table, "<test>", "scene", DATA)[0]
    sd = scenes.load(spec, res)
    w, h = (int(x) for x in sd.sensor.film().size())
    gb = gbuffer.cast(sd.scene, sd.sensor, w, h)
    idx = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    return sd, si


def _from_light(scene, si, light_pos):
    """Independent count: trace from the light toward each receiver; lit iff nothing is hit
    before 99 % of the way (no spawn offsets involved)."""
    o = mi.Point3f(*light_pos)
    d = si.p - o
    dist = dr.norm(d)
    ray = mi.Ray3f(o, d / dist, dist * 0.99, 0.0, mi.Color0f())
    return ~scene.ray_intersect_preliminary(ray).is_valid()


def test_spot_reference_matches_rays_from_the_light():
    light = LightSpec("spot", position=(-1.5, 2.0, 3.0), target=(0, 0, 0), cutoff=40.0)
    sd, si = _setup({"builtin": "plane_box"}, light)
    v_star, dist = reference.visibility(sd.scene, si, light, reference.scene_magnitude(sd.bbox))
    indep = _from_light(sd.scene, si, light.position)
    facing = (dr.dot(si.n, mi.Point3f(*light.position) - si.p) > 0).numpy()
    a, b = v_star.numpy()[facing], indep.numpy()[facing]
    assert (~a).sum() > 500 and a.sum() > 5000      # both shadow and light are present
    assert (a == b).mean() > 0.999
    d = dist.numpy()[facing]
    assert np.all(np.isfinite(d[~a])) and np.all(np.isinf(d[a]))


def test_xml_spot_scene_reference():
    cfg = config.parse({"scene": [{"file": str(DATA / "spot_scene.xml")}], "scheme": [{"name": "none"}]},
                       "<test>", DATA)
    sd = scenes.load(cfg.scenes[0], (128, 128))
    lights = sd.lights_for(cfg.lights)
    assert [l.type for l in lights] == ["spot"]
    assert lights[0].cutoff == pytest.approx(35.0)
    assert np.allclose(lights[0].position, (1, 5, 1), atol=1e-5)
    w, h = (int(x) for x in sd.sensor.film().size())
    assert (w, h) == (128, 96)                     # the XML film's aspect is kept
    gb = gbuffer.cast(sd.scene, sd.sensor, w, h)
    idx = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    v_star, _ = reference.visibility(sd.scene, si, lights[0], reference.scene_magnitude(sd.bbox))
    indep = _from_light(sd.scene, si, lights[0].position)
    facing = (dr.dot(si.n, mi.Point3f(*lights[0].position) - si.p) > 0).numpy()
    assert (v_star.numpy()[facing] == indep.numpy()[facing]).mean() > 0.995


@pytest.mark.parametrize("light", [LightSpec("directional", direction=(-0.4, -0.3, -1.0)),
                                   LightSpec("spot", position=(-1.5, 2.0, 3.0), target=(0, 0, 0), cutoff=40.0)])
def test_scale_relative_spawn_agrees_with_mitsuba_at_unit_scale(light):
    sd, si = _setup({"builtin": "plane_box"}, light)
    ours, _ = reference.visibility(sd.scene, si, light, reference.scene_magnitude(sd.bbox))
    theirs, _ = reference.visibility(sd.scene, si, light, mitsuba_spawn=True)
    assert (ours.numpy() == theirs.numpy()).mean() > 0.999


def test_mitsuba_spawn_breaks_at_millimetre_scale_and_ours_does_not():
    """Why the reference uses the scene's magnitude: Mitsuba's unit term is 9 % of a 1 mm box."""
    light = LightSpec("directional", direction=(-0.4, -0.3, -1.0))
    counts = {}
    for s in (1e-3, 1.0):
        sd, si = _setup({"builtin": "plane_box", "scale": s}, light)
        ours, _ = reference.visibility(sd.scene, si, light, reference.scene_magnitude(sd.bbox))
        theirs, _ = reference.visibility(sd.scene, si, light, mitsuba_spawn=True)
        counts[s] = ((~ours.numpy()).sum(), (~theirs.numpy()).sum())
    assert counts[1e-3][0] == counts[1.0][0]          # ours: the same shadow at both scales
    assert counts[1e-3][1] < counts[1.0][1]           # Mitsuba's unit term shrinks the tiny shadow
