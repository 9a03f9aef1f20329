"""Point lights: paraboloid, dual-paraboloid and cube views (Brabec et al. 2002; Dou et al. 2014 section 3.2)."""

import numpy as np
import pytest

from conftest import ROOT, assert_nan_only_where_undefined, base_config

POINT_VIEWS = ("paraboloid", "dual_paraboloid", "cube")


def _room():
    from dsm.config import read as config
    from dsm.scenes import gbuffer, load as scenes
    cfg = config.parse(base_config(scene=[{"builtin": "room"}]), "<test>")
    sd = scenes.load(cfg.scenes[0], (160, 160))
    gb = gbuffer.cast(sd.scene, sd.sensor, 160, 160)
    return sd, gb


def _np(v):
    return np.stack([np.asarray(c, np.float64) for c in (v.x.numpy(), v.y.numpy(), v.z.numpy())], axis=1)


def _view(kind, light, R, bbox):
    from dsm.config.read import LightSpec
    from dsm.pipeline import make_view
    return make_view(LightSpec("point", position=tuple(light), direction=(0.0, 0.0, -1.0)), R, None, bbox, kind)


def test_every_room_receiver_is_in_exactly_one_map(variant):
    """Each receiver's chosen face holds it (closed domain); no other face holds it in its interior.
    The domains are recomputed here from Brabec et al.'s formulas, independently of dsm.maps.views."""
    import drjit as dr
    import mitsuba as mi
    sd, gb = _room()
    light = np.array([0.2, 0.1, 1.8])
    pix = mi.UInt32(np.flatnonzero(gb.hit).astype(np.uint32))
    p = dr.gather(mi.Point3f, gb.p, pix)
    q = _np(p) - light
    R = 64
    for kind in POINT_VIEWS:
        view = _view(kind, light, R, sd.bbox)
        u, v, face = (a.numpy() for a in view.project(p))
        assert np.all(np.isfinite(u)) and np.all(np.isfinite(v))
        inside = view.inside(p).numpy().astype(bool)
        if kind == "cube":
            from dsm.maps.views import CUBE_FACES
            dom_closed, dom_open = [], []
            for U, V, W in np.asarray(CUBE_FACES, float):
                z = q @ W
                x, y = (q @ U) / np.where(z > 0, z, 1), (q @ V) / np.where(z > 0, z, 1)
                dom_closed.append((z > 0) & (np.abs(x) <= 1 + 1e-6) & (np.abs(y) <= 1 + 1e-6))
                dom_open.append((z > 0) & (np.abs(x) < 1 - 1e-6) & (np.abs(y) < 1 - 1e-6))
            uu, vv = (u / R) * 2 - 1, (v / R) * 2 - 1
        else:
            ex, ey, ez = view.axes_np
            r = np.linalg.norm(q, axis=1)
            dom_closed, dom_open = [], []
            for s in ((1.0, -1.0) if kind == "dual_paraboloid" else (1.0,)):
                den = r + s * (q @ ez)
                ok = den > 1e-9 * r
                x, y = (q @ ex) / np.where(ok, den, 1), (q @ ey) / np.where(ok, den, 1)
                rho = np.hypot(x, y)
                dom_closed.append(ok & (rho <= 1 + 1e-5))
                dom_open.append(ok & (rho < 1 - 1e-5))
            uu, vv = (u / R) * 2 - 1, (v / R) * 2 - 1
        dom_closed, dom_open = np.array(dom_closed), np.array(dom_open)
        mine = dom_closed[face, np.arange(len(face))]
        assert mine[inside].all(), kind
        others = dom_open.sum(axis=0) - dom_open[face, np.arange(len(face))]
        assert (others[inside] == 0).all(), kind
        if kind != "paraboloid":
            assert inside.all(), kind            # dual paraboloid and cube cover every direction
        else:
            assert 0.2 < inside.mean() < 0.9     # one hemisphere of the room
        assert np.abs(uu[inside]).max() <= 1 + 1e-5 and np.abs(vv[inside]).max() <= 1 + 1e-5 or kind != "cube"


@pytest.mark.parametrize("kind", ("orthographic", "perspective") + POINT_VIEWS)
def test_texel_size_is_the_texel_footprint_on_every_view(variant, kind):
    """texel_world(p) = sqrt(area of the texel's footprint on the plane through p normal to the ray):
    measured from the rays through the texel's four corners, so '1 texel' means the same on every view."""
    import mitsuba as mi
    from dsm.maps.views import OrthographicView, PerspectiveView
    R = 256
    bbox = (np.array([-4.0, -4, -4]), np.array([4.0, 4, 4]))
    rng = np.random.default_rng(3)
    light = np.array([0.3, -0.2, 0.4])
    if kind == "orthographic":
        view = OrthographicView((0.2, 0.1, -1), np.array([[-3, -3, -3], [3, 3, 3.0]]), bbox, R)
    elif kind == "perspective":
        view = PerspectiveView(light, (0.1, 0.2, -1), 50, bbox, R)
    else:
        view = _view(kind, light, R, bbox)
    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    if kind == "perspective":
        dirs = dirs[(dirs @ view.axes_np[2]) > 0.9]
    if kind == "paraboloid":
        dirs = dirs[(dirs @ view.axes_np[2]) > 0.05]
    pts = light + dirs * rng.uniform(0.5, 3.0, size=(len(dirs), 1))
    if kind == "orthographic":
        pts = rng.uniform(-2.5, 2.5, size=(300, 3))
    p = mi.Point3f(*(pts[:, k] for k in range(3)))
    u, v, face = view.project(p)
    tw = view.texel_world(p).numpy()
    # the texel's corners around the receiver's map position, each corner's ray met with the plane
    # through p perpendicular to the ray toward p
    o_c, d_c = view.ray_at(u, v, face)
    nrm = _np(d_c)
    corners = []
    for du, dv in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
        o, d = view.ray_at(u + du, v + dv, face)
        o, d = _np(o), _np(d)
        t = np.einsum("ij,ij->i", pts - o, nrm) / np.einsum("ij,ij->i", d, nrm)
        corners.append(o + d * t[:, None])
    a, b, c, e = corners
    area = 0.5 * np.linalg.norm(np.cross(c - a, e - b), axis=1)
    np.testing.assert_allclose(tw, np.sqrt(area), rtol=0.02)


def _point_case(light, views, R, schemes, scene=None, direction=(0.0, 0.0, -1.0)):
    return base_config(scene=[scene or {"builtin": "plane_box"}], camera={"resolution": [160, 160]},
                       light=[{"type": "point", "position": list(light), "direction": list(direction)}],
                       map={"resolution": R, "view": list(views)}, scheme=schemes)


SINGULAR = {
    # receivers straight below the light: the front paraboloid's singular direction (z -> -1 for d0)
    "paraboloid_pole": ((0.3, -2.5, 3.0), (0.0, 0.0, 1.0)),
    # the seam plane z = 0.5 cuts the box's lit side: receivers on the hemisphere seam
    "seam": ((1.6, -0.2, 0.5), (0.0, 0.0, 1.0)),
    # |dx| = |dz| and |dx| = |dy| on the ground: cube edges and corners
    "cube_edges": ((0.0, 0.0, 2.0), (0.0, 0.0, -1.0)),
}


@pytest.mark.slow
@pytest.mark.parametrize("where", sorted(SINGULAR))
def test_singular_directions_stay_finite_and_accurate(run_dict, where):
    light, axis = SINGULAR[where]
    cfg = _point_case(light, POINT_VIEWS, 1024, [{"name": "adaptive"}, {"name": "dual"}], direction=axis)
    res = run_dict(cfg)
    assert len(res) == 6 and not [s for s in res.run["status"] if s["status"] == "failed"]
    for r in res.rows:
        assert_nan_only_where_undefined(r)
        if r["n_receivers"] == 0:
            assert r["view"] == "paraboloid"      # the whole scene behind a hemispherical light
            continue
        assert r["acne_rate"] < 0.02, (where, r["view"], r["scheme"], r["acne_rate"])
        if r["n_gt_shadowed"]:
            assert r["peterpan_rate"] < 0.05, (where, r["view"], r["scheme"], r["peterpan_rate"])
        if r["n_seam"] > 0:                     # (no receiver near a seam: the seam rate is undefined)
            assert r["seam_error_rate"] <= max(0.02, 3 * r["off_seam_error_rate"]), (where, r["view"], r["scheme"])
        if (where, r["view"]) in (("seam", "dual_paraboloid"), ("cube_edges", "cube")):
            assert r["n_seam"] > 0              # the case really puts receivers on the seam


def test_points_exactly_on_singular_directions(variant):
    """Receivers placed exactly on the paraboloid pole, the seam and cube edges and corners:
    one face, a position inside it, a finite texel size and a texel index inside the map."""
    import drjit as dr
    import mitsuba as mi
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    from dsm.maps import shadowmap
    from dsm.maps.lookup import nearest_tap
    from dsm.maps.receiver import Receiver
    cfg = config.parse(base_config(scene=[{"builtin": "plane_box"}]), "<test>")
    sd = scenes.load(cfg.scenes[0], (32, 32))
    light = np.array([0.0, 0.0, 2.0])
    offsets = np.array([[0, 0, -2.0], [0, 0, 2.0], [2, 0, 0], [-2, 0, 0], [2, 2, 0], [2, -2, 0], [2, 0, -2],
                        [2, 2, -2], [-2, -2, -2], [1e-30, 0, -1], [0, -1e-30, -1], [1, 1, 1e-30]])
    pts = light + offsets
    p = mi.Point3f(*(pts[:, k] for k in range(3)))
    n = dr.zeros(mi.Vector3f, len(pts)) + mi.Vector3f(0, 0, 1)
    R = 32
    for kind in POINT_VIEWS:
        for axis in ((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)):
            from dsm.config.read import LightSpec
            from dsm.pipeline import make_view
            view = make_view(LightSpec("point", position=tuple(light), direction=axis), R, None, sd.bbox, kind)
            smap = shadowmap.build(sd.scene, view, {"z2"})
            rx = Receiver.make(view, p, n, sd.diagonal)
            tap = nearest_tap(rx, smap)
            inside = view.inside(p).numpy().astype(bool)
            for arr in (rx.u_map, rx.v_map, rx.texel_world, rx.depth, tap.z1, tap.z2):
                assert np.all(np.isfinite(arr.numpy()[inside])), (kind, axis)
            assert np.all(rx.texel_world.numpy()[inside] > 0)
            idx = tap.idx.numpy()
            assert idx.max() < view.n_texels
            u, v = rx.u_map.numpy()[inside], rx.v_map.numpy()[inside]
            if kind == "cube":
                assert np.all((u >= 0) & (u <= R) & (v >= 0) & (v <= R)), (u, v)
            else:
                rho = np.hypot(2 * u / R - 1, 2 * v / R - 1)
                assert np.all(rho <= 1 + 1e-6), (kind, axis, rho)
            if kind != "paraboloid":
                assert inside.all()


def test_point_reference_matches_an_independent_shadow_ray_count(variant):
    """V* of the ground under a box from a point light equals a slab test of each segment in numpy."""
    import drjit as dr
    import mitsuba as mi
    from dsm.config import read as config
    from dsm.scenes import gbuffer, load as scenes
    from dsm.truth import reference
    from dsm.config.read import LightSpec
    cfg = config.parse(base_config(scene=[{"builtin": "plane_box"}]), "<test>")
    sd = scenes.load(cfg.scenes[0], (256, 256))
    gb = gbuffer.cast(sd.scene, sd.sensor, 256, 256)
    ground = sd.shape_names.index("ground")
    sel = np.flatnonzero(gb.hit & (gb.shape.numpy() == ground))
    light = np.array([-0.9, 1.1, 2.0])
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, mi.UInt32(sel.astype(np.uint32)))
    vis, _ = reference.visibility(sd.scene, si, LightSpec("point", position=tuple(light)),
                                  reference.scene_magnitude(sd.bbox))
    vis = vis.numpy().astype(bool)
    x = _np(si.p)
    d = light - x
    lo, hi = np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - x) / d, (hi - x) / d
    tmin = np.nanmax(np.minimum(t0, t1), axis=1)
    tmax = np.nanmin(np.maximum(t0, t1), axis=1)
    blocked = (tmax >= np.maximum(tmin, 0)) & (tmin <= 1)
    assert 0.03 < blocked.mean() < 0.5                       # a real shadow is in view
    agree = (vis == ~blocked).mean()
    assert agree > 0.998, agree


@pytest.mark.slow
@pytest.mark.parametrize("kind", POINT_VIEWS)
def test_scale_invariance_per_view(run_dict, kind):
    schemes = [{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}, {"name": "adaptive"},
               {"name": "dual"}]
    rates = {}
    for s in (1e-3, 1.0, 1e3):
        cfg = base_config(scene=[{"builtin": "room", "scale": s}], camera={"resolution": [128, 128]},
                          map={"resolution": 256, "view": kind}, scheme=schemes)
        res = run_dict(cfg, name=f"s{s:g}")
        assert len(res) == len(schemes)
        rates[s] = np.array([[r["acne_rate"], r["peterpan_rate"]] for r in res.rows])
    for s in (1e-3, 1e3):
        assert np.abs(rates[s] - rates[1.0]).max() < 0.01, (kind, s, rates[s], rates[1.0])


@pytest.mark.slow
def test_xml_scene_with_a_point_emitter(run_dict):
    cfg = base_config(scene=[{"file": str(ROOT / "tests" / "data" / "point_scene.xml")}],
                      map={"resolution": 256, "view": ["dual_paraboloid", "cube"]},
                      scheme=[{"name": "none"}, {"name": "adaptive"}])
    res = run_dict(cfg)
    assert sorted({r["view"] for r in res.rows}) == ["cube", "dual_paraboloid"]
    assert all(r["light"].endswith("point") for r in res.rows)
    for r in res.where(scheme="adaptive").rows:
        assert r["n_receivers"] > 1000 and r["n_gt_shadowed"] > 100
        assert r["acne_rate"] < 0.02 and r["peterpan_rate"] < 0.05
    for r in res.where(scheme="none").rows:
        assert r["acne_rate"] > 0.2                          # no bias: self-shadowing on every view


@pytest.mark.slow
def test_equal_memory_budgets(run_dict):
    cfg = base_config(scene=[{"builtin": "room"}], camera={"resolution": [64, 64]},
                      map={"texels": [6 * 64 ** 2], "view": ["paraboloid", "dual_paraboloid", "cube"]},
                      scheme=[{"name": "none"}])
    res = run_dict(cfg, report=True)
    got = {r["view"]: (r["resolution"], r["total_texels"]) for r in res.rows}
    assert got == {"paraboloid": (157, 157 ** 2), "dual_paraboloid": (111, 2 * 111 ** 2), "cube": (64, 6 * 64 ** 2)}
    assert (res.out / "plots" / "vs_texels_room_0_point.png").is_file()
    from dsm.config.read import ConfigError, parse
    with pytest.raises(ConfigError, match="map"):
        parse(base_config(map={"texels": 1000, "resolution": 64}), "<test>")


def test_paraboloid_texel_rays_are_dou_et_als_reflected_rays(variant):
    """Dou et al. 2014, section 3.2: R = 2 (d0 . N) N - d0, N the paraboloid normal (x_c, y_c, 1) normalized,
    through the texel centre (x_c, y_c); and projecting R's direction gives the centre back."""
    import mitsuba as mi
    R = 64
    view = _view("paraboloid", (0.0, 0.0, 0.0), R, (np.array([-1.0, -1, -1]), np.array([1.0, 1, 1])))
    ex, ey, ez = view.axes_np
    i, j = np.meshgrid(np.arange(R) + 0.5, np.arange(R) + 0.5)
    u, v = i.ravel(), j.ravel()
    _, d = view.ray_at(mi.Float(u), mi.Float(v))
    d = _np(d)
    xc, yc = 2 * u / R - 1, 2 * v / R - 1
    N = np.stack([xc, yc, np.ones_like(xc)], 1)
    N /= np.linalg.norm(N, axis=1)[:, None]
    d0 = np.array([0, 0, 1.0])
    Rl = 2 * (N @ d0)[:, None] * N - d0
    expected = Rl[:, :1] * ex + Rl[:, 1:2] * ey + Rl[:, 2:] * ez
    np.testing.assert_allclose(d, expected, atol=2e-6)
    pu, pv, _ = view.project(mi.Point3f(*(d[:, k] for k in range(3))))
    np.testing.assert_allclose(pu.numpy(), u, atol=2e-4)
    np.testing.assert_allclose(pv.numpy(), v, atol=2e-4)
