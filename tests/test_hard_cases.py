"""Hard cases against an independent float64 tracer: grazing light, degenerate meshes, light
along the world axes, receivers exactly on texel boundaries.

The expected receivers and exact visibility come from ``Scene64``: the same quads and boxes
as the scene, intersected in float64 numpy from the camera's own rays (no Mitsuba ray cast, no
kit code). A pixel whose answer changes when its ray is tilted by 2e-5 rad (it grazes an edge
or a contact) is *ambiguous* and the only place where the kit may differ.
"""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import base_config

ALL_SCHEMES = [{"name": "none"}, {"name": "constant"}, {"name": "slope_scaled"}, {"name": "normal_angle"},
               {"name": "normal_offset"}, {"name": "receiver_plane"}, {"name": "adaptive"}]
# schemes with a positive bias on a receiver facing the light head-on (none, slope_scaled's API
# default of 2^-24 range and normal_angle's bias * tan(0) leave only rounding there)
BIASED_AT_NORMAL_INCIDENCE = ("constant", "normal_offset", "receiver_plane", "adaptive")


# ---------------------------------------------------------------- the independent expectation

class Scene64:
    """Quads and axis-aligned boxes traced in float64 (the expected values of these tests)."""

    def __init__(self):
        self.parts = []                 # (shape name, "quad" | "box", data)

    def quad(self, name, center, u_half, v_half):
        self.parts.append((name, "quad", tuple(np.asarray(a, float) for a in (center, u_half, v_half))))
        return self

    def box(self, name, lo, hi):
        self.parts.append((name, "box", (np.asarray(lo, float), np.asarray(hi, float))))
        return self

    @staticmethod
    def slabs(lo, hi, o, d):
        """(t_in, t_out, entry axis) of rays (o, d) through the box [lo, hi]; t_in > t_out: a miss."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (lo - o) / d, (hi - o) / d
        near, far = np.minimum(t0, t1), np.maximum(t0, t1)
        inside = (o >= lo) & (o <= hi)             # rays parallel to a slab: in it or not
        near = np.where(d == 0, np.where(inside, -np.inf, np.inf), near)
        far = np.where(d == 0, np.where(inside, np.inf, -np.inf), far)
        return near.max(axis=1), far.min(axis=1), near.argmax(axis=1)

    def entry(self, part, o, d):
        """(t, unit normal) where each ray enters one part; inf where it misses."""
        _, kind, data = self.parts[part]
        if kind == "quad":
            c, u, v = data
            n = np.cross(u, v)
            den = d @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((c - o) @ n) / den
            q = o + t[:, None] * d - c
            ok = (den != 0) & (np.abs(q @ u) <= u @ u) & (np.abs(q @ v) <= v @ v)
            return np.where(ok, t, np.inf), np.broadcast_to(n / np.linalg.norm(n), d.shape)
        t_in, t_out, axis = self.slabs(*data, o, d)
        n = np.zeros_like(d)
        rows = np.arange(len(d))
        n[rows, axis] = -np.sign(d[rows, axis])
        return np.where(t_in <= t_out, t_in, np.inf), n

    def first_hit(self, o, d, tmin=0.0):
        """(t, part index, unit normal) of each ray's first surface beyond ``tmin`` (inf, -1: none)."""
        best, part, normal = np.full(len(d), np.inf), np.full(len(d), -1), np.zeros_like(d)
        for k in range(len(self.parts)):
            t, n = self.entry(k, o, d)
            closer = (t > tmin) & (t < best)
            best, part = np.where(closer, t, best), np.where(closer, k, part)
            normal[closer] = n[closer]
        return best, part, normal


def camera_rays(sensor):
    """The camera's rays through pixel centres (Mitsuba's sensor, as float64 arrays)."""
    W, H = (int(x) for x in sensor.film().size())
    idx = dr.arange(mi.UInt32, W * H)
    x, y = mi.Float(idx % W) + 0.5, mi.Float(idx // W) + 0.5
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / W, y / H), mi.Point2f(0.5, 0.5))
    as64 = lambda v: np.stack([np.asarray(c.numpy(), np.float64) for c in (v.x, v.y, v.z)], axis=1)
    return as64(ray.o), as64(ray.d)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _pixel_truth(scene, o, d, light_dir):
    t, part, n = scene.first_hit(o, d)
    hit = np.isfinite(t)
    p = o + np.where(hit, t, 0.0)[:, None] * d
    n = n * np.where((n * d).sum(1) > 0, -1.0, 1.0)[:, None]          # toward the camera
    to_light = np.broadcast_to(-_unit(np.asarray(light_dir, float)), p.shape)
    receiver = hit & ((n * to_light).sum(1) > 0)
    t_occ, _, _ = scene.first_hit(p, to_light, tmin=1e-9)
    return {"hit": hit, "receiver": receiver, "vstar": ~np.isfinite(t_occ), "part": part, "p": p, "n": n}


def truth(scene, sensor, light_dir, tilt=2e-5):
    """Expected hit, receiver, V* (and hit point, part) per pixel, and which pixels are ambiguous."""
    o, d = camera_rays(sensor)
    base = _pixel_truth(scene, o, d, light_dir)
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = _unit(np.cross(d, helper))
    e2 = np.cross(d, e1)
    amb = np.zeros(len(d), bool)
    for e in (e1, -e1, e2, -e2):
        other = _pixel_truth(scene, o, _unit(d + tilt * e), light_dir)
        for k in ("hit", "receiver", "vstar", "part"):
            amb |= other[k] != base[k]
    base["ambiguous"] = amb
    return base


def assert_matches_truth(res, row, tr):
    """The case's receivers and exact visibility, pixel by pixel and as counts, are the tracer's."""
    from dsm.truth.metrics import ACNE, LIT, OUTSIDE, base_class
    img = base_class(res.images[row["case"]].ravel())
    amb = tr["ambiguous"]
    rec, vstar = img != OUTSIDE, np.isin(img, (LIT, ACNE))
    bad = np.flatnonzero((rec != tr["receiver"]) & ~amb)
    assert bad.size == 0, (row["case"], "receivers differ at pixels", bad[:8], tr["p"][bad[:8]],
                           {k: row[k] for k in row if k.startswith("n_excluded")})
    bad = np.flatnonzero((vstar != tr["vstar"]) & rec & ~amb)
    assert bad.size == 0, (row["case"], "V* differs at pixels", bad[:8], tr["p"][bad[:8]])
    n_amb = int(amb.sum())
    expected = {"n_receivers": tr["receiver"].sum(), "n_gt_shadowed": (tr["receiver"] & ~tr["vstar"]).sum(),
                "n_gt_lit": (tr["receiver"] & tr["vstar"]).sum(), "n_excluded_nohit": (~tr["hit"]).sum(),
                "n_excluded_backfacing": (tr["hit"] & ~tr["receiver"]).sum(), "n_excluded_outside": 0}
    for k, v in expected.items():
        assert abs(int(row[k]) - int(v)) <= n_amb, (row["case"], k, row[k], int(v), n_amb)


def outline_distance(points, polygon, light_dir):
    """Distance, in the plane perpendicular to the light, from each point's projection to the
    outline of the convex polygon's projection (its corners in order)."""
    ez = _unit(np.asarray(light_dir, float))
    e1 = _unit(np.cross(ez, [0.0, 0.0, 1.0] if abs(ez[2]) < 0.9 else [1.0, 0.0, 0.0]))
    e2 = np.cross(ez, e1)
    q = np.stack([points @ e1, points @ e2], axis=1)
    c = np.stack([polygon @ e1, polygon @ e2], axis=1)
    dist = np.full(len(q), np.inf)
    for a, b in zip(c, np.roll(c, -1, axis=0)):
        s = np.clip(((q - a) @ (b - a)) / ((b - a) @ (b - a)), 0.0, 1.0)
        dist = np.minimum(dist, np.linalg.norm(q - (a + s[:, None] * (b - a)), axis=1))
    return dist


def assert_errors_only_at_the_outline(res, row, tr, polygon, light_dir):
    """A planar receiver facing the light with a positive bias is wrong only where its texel's
    centre ray and its own light ray fall on different sides of the caster's outline: within
    half a texel diagonal of it. The texel is at most (receivers' span in the light plane) / R."""
    from dsm.truth.metrics import ACNE, ACNE_RESOLUTION, PETERPAN, PETERPAN_RESOLUTION
    img = res.images[row["case"]].ravel()
    ez = _unit(np.asarray(light_dir, float))
    p = tr["p"][tr["receiver"]]
    flat = p - np.outer(p @ ez, ez)
    span = np.linalg.norm(flat.max(axis=0) - flat.min(axis=0))
    bound = span / row["resolution"] * math.sqrt(0.5) * 1.001
    err = np.isin(img, (ACNE, PETERPAN, ACNE_RESOLUTION, PETERPAN_RESOLUTION)) & ~tr["ambiguous"]
    dist = outline_distance(tr["p"][err], polygon, light_dir)
    assert np.all(dist <= bound), (row["case"], row["scheme"], np.sort(dist)[-5:], bound)


def _config_scene(cfg):
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    c = config.parse(cfg, "<test>")
    return [scenes.load(spec, c.camera_resolution) for spec in c.scenes]


# ---------------------------------------------------------------- the tests

@pytest.mark.slow
def test_grazing_angles_against_the_tracer_and_the_acne_law(run_dict):
    """Ground and box lit 80, 85 and 89 degrees from the ground's normal.

    Receivers and V* are the tracer's, pixel by pixel. Acne follows from geometry alone: in a
    nearest lookup a planar receiver at angle theta to the light has d - z1 = tan(theta) * delta,
    delta its offset from its texel's centre along the depth gradient (here a map axis: the
    light's frame has ex in the plane of the light and the ground's normal), uniform over a texel
    width w. With a bias of k texels it is acne when delta > k w / tan(theta): a rate of
    max(0, 1/2 - k / tan(theta)). none: k = 0; constant: k = 1; normal_angle: k = min(8, tan(theta)).
    """
    angles = [80.0, 85.0, 89.0]
    cfg = base_config(scene=[{"builtin": "grazing", "angle": angles}], map={"resolution": 256},
                      scheme=ALL_SCHEMES)
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    assert len(res) == 3 * len(ALL_SCHEMES)
    for sd, angle in zip(_config_scene(cfg), angles):
        t = math.radians(angle)
        light = (math.sin(t), 0.0, -math.cos(t))
        scene = Scene64().quad("ground", [0, 0, 0], [4, 0, 0], [0, 4, 0]).box("box", [-2.3, -0.3, 0.0],
                                                                              [-1.7, 0.3, 0.6])
        tr = truth(scene, sd.sensor, light)
        assert tr["receiver"].sum() > 20000 and (tr["receiver"] & ~tr["vstar"]).sum() > 1000
        rows = {r["scheme"]: r for r in res.where(scene=sd.label).rows}
        assert len(rows) == len(ALL_SCHEMES)
        tan = math.tan(t)
        law = lambda k: max(0.0, 0.5 - k / tan)
        for r in rows.values():
            assert_matches_truth(res, r, tr)
        for scheme, k in (("none", 0.0), ("constant", 1.0), ("normal_angle", min(8.0, tan))):
            assert rows[scheme]["acne_rate"] == pytest.approx(law(k), abs=0.02), (angle, scheme, law(k))
        for scheme in ("receiver_plane", "adaptive"):    # a plane compared with itself: no self acne
            assert rows[scheme]["n_acne_self"] <= 1e-3 * rows[scheme]["n_gt_lit"], (angle, scheme)


def _write_degenerate_obj(path):
    v = [(-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3),          # ground (y up)
         (-0.5, 0.3, -0.5), (0.5, 0.3, -0.5), (0.5, 0.3, 0.5), (-0.5, 0.3, 0.5),   # a floating plate
         (0, 0.6, 0), (1, 0.6, 0), (2, 0.6, 0), (0, 0.6, 0)]        # collinear points and a repeated vertex
    f = [(1, 3, 2), (1, 4, 3), (5, 7, 6), (5, 8, 7),
         (5, 7, 6), (5, 8, 7),            # duplicated triangles
         (9, 10, 11), (9, 12, 10), (9, 9, 9)]   # zero-area triangles
    with open(path, "w") as fh:
        fh.writelines(f"v {a} {b} {c}\n" for a, b, c in v)
        fh.writelines(f"f {a} {b} {c}\n" for a, b, c in f)


@pytest.mark.slow
def test_degenerate_mesh(run_dict, tmp_path):
    """Duplicated and zero-area triangles change nothing: receivers and V* are those of the
    ground and the plate alone, and the biased schemes err only at the plate's shadow outline."""
    obj = tmp_path / "degenerate.obj"
    _write_degenerate_obj(obj)
    light = [0.3, -1.0, 0.2]
    cfg = base_config(scene=[{"file": str(obj), "ground": "no"}], scheme=ALL_SCHEMES,
                      light=[{"type": "directional", "direction": light}], map={"resolution": 128})
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    plate = np.array([[-0.5, 0.3, -0.5], [0.5, 0.3, -0.5], [0.5, 0.3, 0.5], [-0.5, 0.3, 0.5]])
    scene = Scene64().quad("ground", [0, 0, 0], [3, 0, 0], [0, 0, 3]).quad("plate", [0, 0.3, 0], [0.5, 0, 0],
                                                                           [0, 0, 0.5])
    tr = truth(scene, _config_scene(cfg)[0].sensor, light)
    assert tr["receiver"].sum() > 5000 and (tr["receiver"] & ~tr["vstar"]).sum() > 80
    for r in res.rows:
        assert_matches_truth(res, r, tr)
        if r["scheme"] != "none":
            assert_errors_only_at_the_outline(res, r, tr, plate, light)


def _axis_scene(folder, direction, width):
    """A 4 x 4 receiver square facing the light head-on and, 0.9 in front of it, a 1 x 1 x 0.2
    box whose sides are exactly parallel to the light (n . l = 0: not receivers); the camera
    looks from the light's side, 55 degrees off its axis, so it sees the shadow under the box.
    Returns the tracer's scene and the box's face toward the receiver (the shadow's caster)."""
    d = np.asarray(direction, float)
    k = int(np.flatnonzero(d)[0])
    e1, e2 = (np.eye(3)[j] for j in range(3) if j != k)
    c = -1.0 * d + 0.3 * e1 + 0.2 * e2
    half = 0.5 * (e1 + e2) + 0.1 * np.abs(d)
    lo, hi = c - half, c + half
    scene = Scene64().quad("receiver", [0, 0, 0], 2 * e1, 2 * e2).box("box", lo, hi)
    quad = np.array([-2 * e1 - 2 * e2, 2 * e1 - 2 * e2, 2 * e1 + 2 * e2, -2 * e1 + 2 * e2])
    corners = np.array([[(lo, hi)[i >> j & 1][j] for j in range(3)] for i in range(8)])
    faces = [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
             [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
    obj = lambda v, f: "".join(f"v {a:.17g} {b:.17g} {c:.17g}\n" for a, b, c in v) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
    (folder / "receiver.obj").write_text(obj(quad, [[0, 1, 2], [0, 2, 3]]))
    (folder / "box.obj").write_text(obj(corners, faces))
    cam = -4 * d + 5 * e1 + 3 * e2
    f3 = lambda v: ", ".join(f"{x:g}" for x in v)
    (folder / "scene.xml").write_text(f"""<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="{f3(cam)}" target="0, 0, 0" up="{f3(e2)}"/></transform>
        <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{width}"/></film>
    </sensor>
    <shape type="obj" id="receiver"><string name="filename" value="receiver.obj"/></shape>
    <shape type="obj" id="box"><string name="filename" value="box.obj"/></shape>
</scene>
""")
    bottom = c + 0.1 * d
    caster = np.array([bottom - 0.5 * e1 - 0.5 * e2, bottom + 0.5 * e1 - 0.5 * e2, bottom + 0.5 * e1 + 0.5 * e2,
                       bottom - 0.5 * e1 + 0.5 * e2])
    return scene, caster


@pytest.mark.slow
@pytest.mark.parametrize("direction", [(0, 0, -1), (1, 0, 0), (0, -1, 0), (0, 1, 0), (-1, 0, 0), (0, 0, 1)])
def test_light_parallel_to_world_axes(run_dict, tmp_path, direction):
    """Axis-aligned light: map axes, box edges and texel boundaries line up and the box's sides
    have n . l = 0 exactly. Receivers and V* are the tracer's pixel for pixel; the biased schemes
    err only at the shadow's outline."""
    scene, caster = _axis_scene(tmp_path, direction, 96)
    cfg = base_config(scene=[{"file": str(tmp_path / "scene.xml")}], camera={"resolution": [96, 96]},
                      scheme=ALL_SCHEMES, light=[{"type": "directional", "direction": list(direction)}])
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    assert len(res) == len(ALL_SCHEMES)
    tr = truth(scene, _config_scene(cfg)[0].sensor, direction)
    # the scene is built so that every kind of pixel is there in numbers
    assert tr["receiver"].sum() > 3000 and (tr["receiver"] & ~tr["vstar"]).sum() > 150
    assert (tr["hit"] & ~tr["receiver"]).sum() > 100                    # the box's sides, n . l = 0
    for r in res.rows:
        assert_matches_truth(res, r, tr)
        if r["scheme"] in BIASED_AT_NORMAL_INCIDENCE:
            assert_errors_only_at_the_outline(res, r, tr, caster, direction)


def test_receivers_exactly_on_texel_boundaries():
    """Map positions exactly on texel corners (0, k, R) pick the texel that contains them: texel
    i covers [i, i + 1), so u = k is in texel k, and u = R, past the last texel, is clamped to
    R - 1 for the index but is beyond the map (no caster: the far bound). The texel holds the
    plane's depth at its centre; points built at those corners in world space project there."""
    from dsm.scenes import load as scenes
    from dsm.maps import shadowmap
    from dsm.config.read import parse
    from dsm.maps.lookup import tap_at
    from dsm.maps.receiver import Receiver
    from dsm.maps.views import OrthographicView
    cfg = parse(base_config(), "<test>")                 # a 4 x 4 plane tilted 45 degrees about x
    sd = scenes.load(cfg.scenes[0], (32, 32))
    R = 16
    view = OrthographicView((0, 0, -1), np.array([[-2, -2, 0], [2, 2, 0.0]]), sd.bbox, R)
    ex, ey, ez = view.axes_np
    # light straight down: the light frame is ex = +x, ey = -y, ez = -z
    assert np.allclose(ex, [1, 0, 0]) and np.allclose(ey, [0, -1, 0]) and np.allclose(ez, [0, 0, -1])
    smap = shadowmap.build(sd.scene, view, set())
    ks = np.array([0.0, 1.0, 7.0, 15.0, 16.0])
    uu, vv = (a.ravel() for a in np.meshgrid(ks, ks))
    w = view.extent / R
    pts = view.origin_np + np.outer(uu * w, ex) + np.outer(vv * w, ey)      # on the map's near plane
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    rx = Receiver.make(view, p, dr.zeros(mi.Vector3f, len(pts)) + mi.Vector3f(0, 0, 1), sd.diagonal)
    np.testing.assert_allclose(rx.u_map.numpy(), uu, rtol=0, atol=1e-4)
    np.testing.assert_allclose(rx.v_map.numpy(), vv, rtol=0, atol=1e-4)
    tap = tap_at(rx, smap, mi.Float(uu.astype(np.float32)), mi.Float(vv.astype(np.float32)))
    i, j = np.minimum(uu, R - 1).astype(int), np.minimum(vv, R - 1).astype(int)
    np.testing.assert_array_equal(tap.idx.numpy(), j * R + i)
    # the texel's centre ray goes straight down through (x, y) and meets the plane z = y
    # (|x| <= 2, |y| <= 2 cos 45 deg) at depth (o - p) . ez = o_z - y, o the map's origin;
    # elsewhere it misses, and past the map's last texel there is no caster: the far bound
    x = view.origin_np[0] + (i + 0.5) * w
    y = view.origin_np[1] - (j + 0.5) * w
    half_y = 2 * math.cos(math.radians(45))
    assert np.all(np.minimum(np.abs(np.abs(x) - 2), np.abs(np.abs(y) - half_y)) > 1e-3)   # no centre on an edge
    inside = (np.abs(x) <= 2) & (np.abs(y) <= half_y) & (uu < R) & (vv < R)
    depth = np.where(inside, view.origin_np[2] - y, view.far)
    assert inside.any() and (~inside).any()
    np.testing.assert_allclose(tap.z1.numpy(), depth, rtol=0, atol=2e-6)
