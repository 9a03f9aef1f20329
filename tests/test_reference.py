"""Reference visibility against independent counts, and the spawn rule against Mitsuba's."""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from dsm.config import read as config
from dsm.scenes import camera as scene_camera, gbuffer, geometry, load as scenes, spec as scene_spec
from dsm.truth import reference
from dsm.scenes import spawn
from dsm.config.read import LightSpec

DATA = Path(__file__).parent / "data"


def _setup(spec_table, light, res=(160, 160)):
    spec = scene_spec.parse_scene(spec_table, "<test>", "scene", DATA)[0]
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


# ---------------------------------------------------------------- far from the origin

def _plate_scene(offset, gap=0.2, res=128):
    """The floating plate (a 1.5 x 1.5 open plate ``gap`` above an 8 x 8 ground), moved by ``offset``."""
    off = np.asarray(offset, float)
    g_v, g_f = geometry.quad(off, [4, 0, 0], [0, 4, 0])
    p_v, p_f = geometry.quad(off + [0, 0, gap], [0.75, 0, 0], [0, 0.75, 0])
    sensor = scene_camera.look_at_sensor(off + [3.0, -5.0, 4.0], off, (0, 0, 1), 40, res, res)
    scene = mi.load_dict({"type": "scene", "ground": geometry.make_mesh("ground", g_v, g_f),
                          "plate": geometry.make_mesh("plate", p_v, p_f), "sensor": sensor}, optimize=False)
    gb = gbuffer.cast(scene, scene.sensors()[0], res, res)
    idx = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    return scene, dr.gather(mi.SurfaceInteraction3f, gb.si, idx)


def _plate_shadow_f64(p, direction, offset, gap):
    """float64 on the plate as stored (float32 corners): (shadowed, distance of the shadow ray's
    crossing of the plate's plane to the plate's edge)."""
    f32 = lambda x: np.float64(np.float32(x))
    off = np.asarray(offset, float)
    lo = np.array([f32(off[0] - 0.75), f32(off[1] - 0.75)])
    hi = np.array([f32(off[0] + 0.75), f32(off[1] + 0.75)])
    z_plate = f32(off[2] + gap)
    to_light = -np.asarray(direction, float) / np.linalg.norm(direction)
    t = (z_plate - p[:, 2]) / to_light[2]
    x = p[:, :2] + t[:, None] * to_light[:2]
    inside_dist = np.minimum(np.min(x - lo, axis=1), np.min(hi - x, axis=1))
    on_plate = np.abs(p[:, 2] - z_plate) < 1e-5 * (1.0 + np.abs(p).max(1))
    return ~on_plate & (t > 0) & (inside_dist > 0), np.abs(inside_dist)


@pytest.mark.parametrize("offset", [(0, 0, 0), (2000, 1500, 100), (1e4, 0, 0), (0, 1e4, 0), (0, 0, 1e4),
                                    (-1e4, -1e4, -1e4)])
def test_reference_exact_far_from_origin(offset):
    """Exact visibility on the kit's own receiver points equals a float64 count wherever the
    shadow edge is further than float32's resolution there; the shadow keeps its size."""
    direction = (0.2, 0.1, -1.0)
    scene, si = _plate_scene(offset)
    light = LightSpec("directional", direction=direction)
    bbox = scene.bbox()
    v_star, _ = reference.visibility(scene, si, light, reference.scene_magnitude(
        (np.array(bbox.min, float).ravel(), np.array(bbox.max, float).ravel())))
    p = np.stack([c.numpy() for c in (si.p.x, si.p.y, si.p.z)], 1).astype(np.float64)
    n = np.stack([c.numpy() for c in (si.n.x, si.n.y, si.n.z)], 1)
    facing = (n @ -np.asarray(direction)) > 0
    shadow64, edge = _plate_shadow_f64(p, direction, offset, 0.2)
    resolvable = edge > 1e-6 * (np.abs(p).max(1) + 10.0)
    ours = ~v_star.numpy()
    keep = facing & resolvable
    assert shadow64[keep].sum() > 150            # the shadow is there: the case tests something
    assert np.array_equal(ours[keep], shadow64[keep])


def test_hit_points_lie_within_a_third_of_the_spawn_offset():
    """Measured: the float32 hit point's distance from the true triangle plane (float64), over
    random rays onto triangles at several distances from the origin, stays below delta / 3."""
    rng = np.random.default_rng(3)
    worst = 0.0
    for centre in ([0, 0, 0], [2000, 1500, 100], [1e4, -1e4, 5e3], [3e5, 0, 0]):
        c = np.asarray(centre, float)
        v = c + rng.uniform(-3, 3, (3, 3))
        scene = mi.load_dict({"type": "scene", "tri": geometry.make_mesh("tri", v, np.array([[0, 1, 2]]))},
                             optimize=False)
        v32 = v.astype(np.float32).astype(np.float64)          # the vertices as stored
        normal = np.cross(v32[1] - v32[0], v32[2] - v32[0])
        normal /= np.linalg.norm(normal)
        b = rng.dirichlet([1, 1, 1], 20000)
        target = b @ v32
        o = target + normal * 5.0 + rng.normal(0, 1.0, target.shape)
        ray = mi.Ray3f(mi.Point3f(*o.T.astype(np.float32)), mi.Vector3f(*(target - o).T.astype(np.float32)))
        si = scene.ray_intersect(ray)
        hit = si.is_valid().numpy()
        p = np.stack([c_.numpy() for c_ in (si.p.x, si.p.y, si.p.z)], 1).astype(np.float64)[hit]
        dist = np.abs((p - v32[0]) @ normal)
        delta = spawn.error_bound(si, mi.Float(0.0)).numpy()[hit]
        assert hit.mean() > 0.95
        worst = max(worst, float((dist / delta).max()))
    assert worst < 1.0 / 3.0
