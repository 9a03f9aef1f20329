"""Exact visibility far from the origin: the G-buffer and the reference traced in a frame centred
on the scene give, at 1e4, 1e5 and 1e6 from the origin, the reference of the scene at the origin,
and both agree with a float64 ray-triangle count (numpy) over the built-in's own float64 triangles."""

import numpy as np
import pytest

from dsm.scenes import builtins as scene_builtins, exact_frame
from dsm import pipeline

OFFSETS = (0.0, 1e4, 1e5, 1e6)


def _setup(builtin, offset, light=None):
    spec = pipeline.scene_spec({"builtin": builtin, "translate": [offset, -0.5 * offset, 0.25 * offset]})
    sd = pipeline.load_scene(spec, (128, 128))
    gb = pipeline.gbuffer(sd)
    light = sd.lights_for([light])[0] if light is not None else sd.own_lights[0]
    return spec, sd, pipeline.light_setup(sd, gb, light, "0")


def _float64_shadowed(spec, sd, setup):
    """V* = 0 by a float64 Moller-Trumbore test of each receiver's ray to the light against the
    built-in's triangles at their float64 world positions (scale, then translate)."""
    shapes, _, _ = scene_builtins.builtin_geometry(spec.builtin, spec.params)
    t = np.asarray(spec.params.translate, float)
    tris = np.concatenate([(np.asarray(v, float) * spec.params.scale + t)[np.asarray(f)] for v, f in shapes.values()])
    p = np.stack([np.asarray(c, np.float64) for c in (setup.si.p.x, setup.si.p.y, setup.si.p.z)], 1)
    p = p + (sd.centre if sd.centre is not None else 0.0)
    light = setup.light
    if light.position is None:
        d = np.broadcast_to(-np.asarray(light.direction, float) / np.linalg.norm(light.direction), p.shape)
        t_max = np.full(len(p), np.inf)
    else:
        d = np.asarray(light.position, float) - p
        t_max = np.linalg.norm(d, axis=1)
        d = d / t_max[:, None]
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    blocked = np.zeros(len(p), bool)
    for k in range(len(tris)):
        h = np.cross(d, e2[k])
        a = h @ e1[k]
        ok = np.abs(a) > 1e-14
        s = p - tris[k, 0]
        u = np.where(ok, (s * h).sum(1) / np.where(ok, a, 1), -1)
        q = np.cross(s, e1[k])
        v = np.where(ok, (d * q).sum(1) / np.where(ok, a, 1), -1)
        tt = np.where(ok, (q @ e2[k]) / np.where(ok, a, 1), -1)
        # 1e-4: beyond the receiver's own triangle (its float32 position is within 1e-6 of it)
        blocked |= ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 1e-4) & (tt < t_max - 1e-4)
    return blocked


def _blocked64(p, d, tris, cells=256):
    """Whether each ray p + t d (t > 1e-4, one direction d for all) meets one of ``tris``: the
    triangles whose bounds, projected along d, hold the ray's projected origin (found through a
    cells x cells grid over the bounds, then tested exactly), then Moller-Trumbore on those pairs
    (float64)."""
    ea = np.cross(d, [1.0, 0, 0] if abs(d[0]) < 0.9 else [0, 1.0, 0])
    ea /= np.linalg.norm(ea)
    eb = np.cross(d, ea)
    basis = np.stack([ea, eb], 1)
    p2, t2 = p @ basis, tris @ basis
    lo, hi = t2.min(1), t2.max(1)
    r, t = _bound_pairs(p2, lo, hi, cells)
    # why a grid: the test of every pair (receivers x 47,794 triangles) took 12 s an offset; a cell's
    # index is monotone in the position, so a bound holding a point spans the point's cell
    t0, e1, e2 = tris[t, 0], tris[t, 1] - tris[t, 0], tris[t, 2] - tris[t, 0]
    h = np.cross(d, e2)
    a = (h * e1).sum(1)
    ok = np.abs(a) > 1e-14
    inv = np.where(ok, 1 / np.where(ok, a, 1), 0)
    s_ = p[r] - t0
    u = (s_ * h).sum(1) * inv
    qv = np.cross(s_, e1)
    v = (qv @ d) * inv
    tt = (qv * e2).sum(1) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 1e-4)
    blocked = np.zeros(len(p), bool)
    np.logical_or.at(blocked, r[hit], True)
    return blocked


def _bound_pairs(p2, lo, hi, cells):
    """(point, box) index pairs of every 2-D box [lo, hi] that holds a point of ``p2``, through a
    uniform grid of cells x cells over the boxes: each box listed in the cells it spans."""
    origin, top = lo.min(0), hi.max(0)
    size = np.maximum(top - origin, 1e-300) / cells
    cell = lambda x: np.clip(np.floor((x - origin) / size).astype(np.int64), 0, cells - 1)
    c_lo, c_hi = cell(lo), cell(hi)
    nx, ny = c_hi[:, 0] - c_lo[:, 0] + 1, c_hi[:, 1] - c_lo[:, 1] + 1
    box = np.repeat(np.arange(len(lo)), nx * ny)
    k = np.arange(len(box)) - np.repeat(np.cumsum(nx * ny) - nx * ny, nx * ny)
    key = (c_lo[box, 0] + k % nx[box]) * cells + c_lo[box, 1] + k // nx[box]
    order = np.argsort(key, kind="stable")
    key, box = key[order], box[order]
    inside = ((p2 >= origin) & (p2 <= top)).all(1)
    pts = np.nonzero(inside)[0]
    pc = cell(p2[pts])
    pkey = pc[:, 0] * cells + pc[:, 1]
    start, end = np.searchsorted(key, pkey, "left"), np.searchsorted(key, pkey, "right")
    n = end - start
    r = np.repeat(pts, n)
    idx = np.repeat(start - (np.cumsum(n) - n), n) + np.arange(n.sum())
    t = box[idx]
    held = ((p2[r] >= lo[t]) & (p2[r] <= hi[t])).all(1)
    return r[held], t[held]


@pytest.mark.slow
def test_a_mesh_far_from_the_origin_keeps_its_reference(variant):
    """The Stanford dragon (47,794 triangles, 0.8 across, data/meshes) on its ground at 0, 1e4 and
    1e5 (at 1e6 float32 holds 13 steps across it: refused in world precision): the same receivers,
    and shadowed ones equal to a float64 ray-triangle count over the mesh's own vertices at their
    float64 world positions."""
    from conftest import MESHES
    counts = {}
    for off in OFFSETS[:3]:
        spec = pipeline.scene_spec({"file": str(MESHES / "dragon_vrip_res3.ply"), "translate": [off, 0.5 * off, 0.0]})
        sd = pipeline.load_scene(spec, (64, 64))
        setup = pipeline.light_setup(sd, pipeline.gbuffer(sd), sd.own_lights[0], "0")
        centre = sd.centre if sd.centre is not None else 0.0
        tris = np.concatenate([np.asarray(sh.vertex_positions_buffer(), np.float64).reshape(-1, 3)[
            np.asarray(sh.faces_buffer(), np.int64).reshape(-1, 3)] for sh in sd.exact.shapes()]) + centre
        p = np.stack([np.asarray(c, np.float64) for c in (setup.si.p.x, setup.si.p.y, setup.si.p.z)], 1) + centre
        d = -np.asarray(setup.light.direction, float) / np.linalg.norm(setup.light.direction)
        exact64 = _blocked64(p, d, tris)
        shadowed = ~setup.v_star
        counts[off] = (len(setup.pixels), int(shadowed.sum()), int((shadowed != exact64).sum()))
    print("dragon (receivers, shadowed, differing from float64) by offset:", counts)
    n0, s0, _ = counts[0.0]
    assert s0 > 100
    for off, (n, s, diff) in counts.items():
        assert n == n0 and abs(s - s0) <= max(2, 0.01 * s0) and diff <= max(2, 0.01 * s), (off, counts)


@pytest.mark.parametrize("builtin, light", [
    ("plane_box", None),
    ("floating_plate", {"type": "point", "position": [0.4, 0.2, 3.0]}),
])
def test_reference_far_from_the_origin_is_the_reference_at_the_origin(variant, builtin, light):
    from dsm.config import read as config
    spec_light = None
    if light is not None:
        spec_light = config.parse({"scene": [{"builtin": builtin}], "light": [light],
                                   "scheme": [{"name": "none"}]}, "x.toml").lights[0]
    counts = {}
    for off in OFFSETS:
        spec, sd, setup = _setup(builtin, off, spec_light)
        assert (sd.centre is None) == (off == 0.0)
        exact64 = _float64_shadowed(spec, sd, setup)
        shadowed = ~setup.v_star
        counts[off] = (len(setup.pixels), int(shadowed.sum()), int((shadowed != exact64).sum()))
        # against float64: at most a few receivers whose ray grazes an edge within float32 rounding
        assert counts[off][2] <= max(2, 0.01 * shadowed.sum()), (off, counts[off])
    print(f"{builtin}: (receivers, shadowed, differing from float64) by offset: {counts}")
    n0, s0, _ = counts[0.0]
    for off in OFFSETS[1:]:
        n, s, _ = counts[off]
        assert abs(n - n0) <= 0.002 * n0 and abs(s - s0) <= max(2, 0.01 * s0), (off, counts)
    assert s0 > 50


def test_world_positions_are_the_exact_frame_plus_the_centre_rounded_once(variant):
    _, sd, setup = _setup("plane_box", 1e5)
    p_x = np.stack([np.asarray(c, np.float64) for c in (setup.si.p.x, setup.si.p.y, setup.si.p.z)], 1)
    p_w = np.stack([np.asarray(c, np.float64) for c in (setup.p.x, setup.p.y, setup.p.z)], 1)
    assert np.array_equal(p_w, (p_x + sd.centre).astype(np.float32).astype(np.float64))


def test_near_scenes_stay_in_world_coordinates():
    assert exact_frame.centre_for((np.array([-1.0, -1, 0]), np.array([1.0, 1, 2]))) is None
    assert exact_frame.centre_for((np.array([9.0, -1, 0]), np.array([11.0, 1, 2]))) is None   # 3 diagonals out
    c = exact_frame.centre_for((np.array([999.0, -1, 0]), np.array([1001.0, 1, 2])))
    assert np.array_equal(c, [1000.0, 0.0, 1.0])


@pytest.mark.slow
def test_camera_relative_map_keeps_its_counts_far_away_and_world_precision_is_flagged(run_dict):
    """At 1e6 a float32 step is 2^(19 - 23) = 0.0625 (1e6 lies in [2^19, 2^20)): the world-precision
    case reports that step and a texel below it, run.json lists it; camera-relative rendering gives
    the counts of the scene at the origin, with the same exact reference in all four."""
    cfg = {"experiment": {"name": "t"}, "camera": {"resolution": [96, 96]}, "map": {"resolution": 256},
           "scene": [{"builtin": "plane_box", "translate": [[0, 0, 0], [1e6, 5e5, 0]],
                      "precision": ["world", "camera_relative"]}],
           "scheme": [{"name": "constant", "bias": "1 texel"}], "timing": {"repeats": 1}}
    res = run_dict(cfg)
    by = {r["scene"]: r for r in res.rows}
    origin, far = by["plane_box"], by["plane_box(translate=[1e+06,500000,0])"]
    rel0, rel = by["plane_box(precision=camera_relative)"], by["plane_box(translate=[1e+06,500000,0],precision=camera_relative)"]
    assert len({r["n_gt_shadowed"] for r in res.rows}) == 1 and len({r["n_receivers"] for r in res.rows}) == 1
    assert far["f32_step"] == 0.0625 and far["texel_f32_steps"] == far["texel_size"] / 0.0625 < 1
    assert res.run["precision_limited"] == [far["case"]]
    for k in ("n_acne", "n_peterpan"):
        assert abs(rel[k] - rel0[k]) <= 2 and abs(rel0[k] - origin[k]) <= 2
    assert far["n_acne"] > 10 * max(origin["n_acne"], 1)          # float32 world coordinates cost acne at 1e6
    assert "## Float32 precision (1 cases)" in (res.out / "table.md").read_text()


def test_precision_choices_are_checked():
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as e:
        config.parse({"scene": [{"builtin": "plane", "precision": "double"}], "scheme": [{"name": "none"}]}, "x.toml")
    assert e.value.key == "scene[0].precision" and "camera_relative" in str(e.value)


def _far_authored_scene(folder, at: float):
    """An XML scene whose OBJ holds a unit box on an 8 x 8 ground, both authored at (at, at, 0) in the
    file's own coordinates (multiples of 1/16: exact in float32 up to 1e6), its camera and light too."""
    v = [(x, y, 0.0) for x, y in ((-4, -4), (4, -4), (4, 4), (-4, 4))]
    v += [(x, y, z) for z in (0.0, 1.0) for x, y in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))]
    faces = [(1, 2, 3), (1, 3, 4)]
    quads = [(5, 8, 7, 6), (9, 10, 11, 12), (5, 6, 10, 9), (6, 7, 11, 10), (7, 8, 12, 11), (8, 5, 9, 12)]
    faces += [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
    obj = "".join(f"v {x + at} {y + at} {z}\n" for x, y, z in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces)
    (folder / "far.obj").write_text(obj)
    (folder / "far.xml").write_text(f"""<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="{at + 3}, {at - 5}, 4" target="{at}, {at}, 0" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="128"/><integer name="height" value="128"/></film></sensor>
  <emitter type="directional"><vector name="direction" x="0.3" y="0.2" z="-1"/></emitter>
  <shape type="obj"><string name="filename" value="far.obj"/></shape>
</scene>
""")
    return folder / "far.xml"


@pytest.mark.slow
def test_a_scene_authored_far_from_the_origin_in_its_own_file_is_exact(tmp_path):
    """The same box and ground authored at 1e6 in their own OBJ (no translate) shadow the ground as
    at the origin: the exact side is traced in the frame centred on the scene (before, its shadow
    rays left the surfaces by 1e6's float32 error and the reference found none of them shadowed).
    At 1e9 float32 cannot hold the 8-unit scene (steps of 64): refused naming the file."""
    import dsm
    from dsm.core.types import ConfigError
    counts = {}
    for at in (0.0, 1e6):
        folder = tmp_path / f"at{at:g}"
        folder.mkdir()
        res = dsm.run({"experiment": {"name": "far"}, "scene": [{"file": str(_far_authored_scene(folder, at))}],
                       "map": {"resolution": 256}, "scheme": [{"name": "constant", "bias": "2 texel"}],
                       "timing": {"repeats": 1}}, out=folder / "run")
        (row,) = res.rows
        counts[at] = (row["n_receivers"], row["n_gt_shadowed"])
    assert counts[0.0][1] > 60                                    # the box's shadow on the ground
    assert counts[1e6] == counts[0.0]
    folder = tmp_path / "at1e9"
    folder.mkdir()
    with pytest.raises(ConfigError) as e:
        dsm.run({"experiment": {"name": "far"}, "scene": [{"file": str(_far_authored_scene(folder, 1e9))}],
                 "scheme": [{"name": "constant"}]}, out=folder / "run")
    assert e.value.key == "scene[0].file" and "1e+09" in str(e.value)


def test_the_grid_finds_every_box_that_holds_a_point_and_no_other():
    """_bound_pairs (the float64 check's grid) against the test of every pair: random boxes, points
    inside, outside and on their corners, and boxes of no extent."""
    rng = np.random.default_rng(7)
    for extent in (0.3, 0.0):
        lo = rng.uniform(0, 10, (800, 2))
        hi = lo + rng.exponential(extent, (800, 2))
        p2 = np.concatenate([rng.uniform(-1, 11, (600, 2)), lo[:100], hi[:100], [[lo[5, 0], hi[5, 1]]]])
        r, t = _bound_pairs(p2, lo, hi, 32)
        want = np.nonzero(((p2[:, None] >= lo[None]) & (p2[:, None] <= hi[None])).all(-1))
        assert sorted(zip(r.tolist(), t.tolist())) == sorted(zip(*(w.tolist() for w in want))) and len(r) >= 201
