"""Second layer, culling and closedness, against layers traced in float64; Weiskopf & Ertl's figure 5 as checked numbers."""

import numpy as np
import pytest

import dsm
from conftest import MESHES, ROOT, base_config
from dsm.scenes.closedness import closedness, weld_ids
from dsm.scenes.geometry import box, prism, quad
from test_hard_cases import Scene64, assert_matches_truth, truth


@pytest.mark.slow
def test_thin_plate_midpoint_and_dual_keep_the_shadow(run_dict):
    cfg = base_config(scene=[{"builtin": "floating_plate", "gap": 0.2}], map={"resolution": 512},
                      camera={"resolution": [256, 256]},
                      scheme=[{"name": "midpoint"}, {"name": "dual", "culling": ["none", "back_closed"]},
                              {"name": "adaptive"}])
    res = run_dict(cfg)
    for r in res.rows:
        assert r["n_gt_shadowed"] > 500
        assert r["peterpan_rate"] < 0.05, r


@pytest.mark.slow
def test_adaptive_scale_invariance_and_planes(run_dict):
    cfg = base_config(scene=[{"builtin": "plane", "tilt": [10.0, 80.0], "scale": [1e-3, 1e3]}],
                      scheme=[{"name": "adaptive"}], map={"resolution": 256})
    res = run_dict(cfg)
    assert len(res.rows) == 4 and all(r["acne_rate"] < 0.005 for r in res.rows)


@pytest.mark.slow
def test_ray_counts_follow_the_needs(run_dict):
    single = run_dict(base_config(scheme=[{"name": "constant"}, {"name": "adaptive"}],
                                  map={"resolution": [32, 64]}), "single")
    assert single.run["rays"]["map_continue"] == 0
    assert single.run["rays"]["map_texel"] == 32 * 32 + 64 * 64
    cfg = base_config(scene=[{"builtin": "floating_plate"}], map={"resolution": 64},
                      scheme=[{"name": "midpoint"}, {"name": "dual", "culling": "none",
                                                       "z_offset": ["1 texel", "4 texel"]},
                              {"name": "constant"}])
    two = run_dict(cfg, "two")
    rays = two.run["rays"]
    # one map serves constant, midpoint and both duals: one texel ray per texel
    assert rays["map_texel"] == 64 * 64
    # second-layer rays: one continuation per texel whose first ray hit the plate or the ground
    # (no culling); counted here by the tracer along the runner's texel rays
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    c = config.parse(cfg, "<test>")
    sd = scenes.load(c.scenes[0], c.camera_resolution)
    view = _runner_view(sd, sd.lights_for(c.lights)[0], 64)
    o, d = _texel_rays(view)
    scene = Scene64().quad("plate", [0, 0, 0.2], [0.75, 0, 0], [0, 0.75, 0]).quad("ground", [0, 0, 0], [4, 0, 0],
                                                                                  [0, 4, 0])
    hit = np.isfinite(scene.first_hit(o, d)[0])
    unsure = np.zeros(len(o), bool)
    for o2 in _shifted(o, view):
        unsure |= np.isfinite(scene.first_hit(o2, d)[0]) != hit
    assert 0 < hit.sum() < len(hit)
    assert abs(rays["map_continue"] - hit.sum()) <= unsure.sum(), (rays, hit.sum(), unsure.sum())
    assert len({r["build_ms"] for r in two.rows if r["scheme"] in ("midpoint", "dual")}) == 1


def test_closedness_detection():
    assert closedness(*box([0, 0, 0], [1, 1, 1])) == (True, "closed")
    assert closedness(*prism([(-1, 0.5), (1, 0.5), (1, 2), (0.7, 2), (0.7, 0.8), (-1, 0.8)], 0, 1, 4))[0]
    closed, why = closedness(*quad([0, 0, 0], [1, 0, 0], [0, 1, 0]))
    assert not closed and "boundary" in why
    v, f = box([0, 0, 0], [1, 1, 1])
    f2 = f.copy()
    f2[0] = f2[0][::-1]                                   # one flipped triangle
    closed, why = closedness(v, f2)
    assert not closed and "winding" in why
    closed, why = closedness(v, np.vstack([f, f[:1]]))    # a duplicated triangle
    assert not closed and "non-manifold" in why
    closed, why = closedness(v, f[:, ::-1])               # closed, wound inward (a room's walls)
    assert closed and "inward" in why


def test_welded_ids_and_edge_counts_match_numpy_unique_by_rows():
    """closedness welds vertices and counts edges by sorting 1-D keys; numpy's row-wise unique
    (np.unique(axis=0)) is the second computation: the same ids (signed zeros welded) and, on random
    meshes with shared, repeated and degenerate triangles, the same edge counts."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        v = rng.integers(-2, 3, (int(rng.integers(3, 30)), 3)).astype(np.float64) * 0.5
        v[rng.random(v.shape) < 0.2] = -0.0
        f = rng.integers(0, len(v), (int(rng.integers(1, 50)), 3))
        _, weld = np.unique(v, axis=0, return_inverse=True)
        assert (weld_ids(v) == weld.ravel()).all()
        g = weld.ravel()[f]
        g = g[(g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 0] != g[:, 2])]
        if not len(g):
            continue
        directed = np.concatenate([g[:, [0, 1]], g[:, [1, 2]], g[:, [2, 0]]])
        _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
        _, dcounts = np.unique(directed, axis=0, return_counts=True)
        closed, why = closedness(v, f)
        assert closed == (bool((counts == 2).all()) and not (dcounts > 1).any())
        assert (f"{int((counts == 1).sum())} boundary edges" in why) == bool((counts == 1).sum())
        assert (f"{int((counts > 2).sum())} non-manifold edges" in why) == bool((counts > 2).sum())


@pytest.mark.slow
def test_dragon_is_open_and_back_closed_culls_only_closed_shapes(tmp_path):
    cfg = base_config(scene=[{"file": str(MESHES / "dragon_vrip_res3.ply")}],
                      light=[{"type": "directional", "direction": [0.3, -1.0, 0.2]}],
                      scheme=[{"name": "dual", "culling": "back_closed"}], map={"resolution": 128})
    res = dsm.run(cfg, out=tmp_path / "d", report=False)
    assert res.run["n_failed"] == 0
    shapes = {s["name"]: s for s in res.run["scenes"][0]["shapes"]}
    assert shapes["mesh"]["closed"] is False and "non-manifold" in shapes["mesh"]["why"]
    assert shapes["ground"]["closed"] is False


def test_back_closed_in_a_mixed_scene(run_dict):
    """l_shape (closed) over the ground (open): back_closed culls the L's back faces only, so the
    second layer behind the L's top is the ground, while an open-only map is unaffected."""
    from dsm.scenes import load as scenes
    from dsm.maps import shadowmap
    from dsm.config.read import parse
    from dsm.maps.views import OrthographicView
    cfg = parse(base_config(scene=[{"builtin": "l_shape"}]), "<test>")
    sd = scenes.load(cfg.scenes[0], (32, 32))
    from dsm.scenes.closedness import shape_closedness
    closed = [shape_closedness(s)[0] for s in sd.scene.shapes()]
    assert dict(zip(sd.shape_names, closed)) == {"ground": False, "l_shape": True}
    modes = shadowmap.cull_modes_for("back_closed", closed)
    view = OrthographicView((0, 0, -1), np.array([[-1, -0.8, 0], [1, 0.8, 0]]), sd.bbox, 32)
    plain = shadowmap.build(sd.scene, view, {"z2"})
    culled = shadowmap.build(sd.scene, view, {"z2"}, "back_closed", modes)
    z1p, z2p, z2c, z1c = (np.array(a) for a in (plain.z1, plain.z2, culled.z2, culled.z1))
    over_l = np.array(plain.shape) == sd.shape_names.index("l_shape")
    assert over_l.sum() > 50
    assert np.allclose(z1c[over_l], z1p[over_l])                 # front faces are never culled
    # without culling z2 is the L's own bottom (0.3 below its top); with back_closed it is the ground
    assert np.all(z2p[over_l] < z2c[over_l])
    ground_depth = np.array(view.depth(__import__("mitsuba").Point3f(0, 0, 0)))[0]
    assert np.allclose(z2c[over_l], ground_depth, atol=1e-4)
    # every texel's layers against the L's surfaces along its ray (float64)
    o, d = _texel_rays(view)
    for smap, cull in ((plain, False), (culled, True)):
        expected = _l_layers(o, d, cull, view.far)
        ok = ~_unsure_layers(o, d, view, cull, expected)
        assert ok.sum() > 0.9 * len(ok)
        assert_layers_match(smap, expected, ok, sd.shape_names.index("l_shape"))


def _texel_rays(view):
    """Centre rays of every texel of an orthographic view, in float64 from the view's frame:
    origins on the view's depth-0 plane, so a hit's depth is its distance t along the ray."""
    R, w = view.resolution, view.extent / view.resolution
    ex, ey, ez = view.axes_np
    j, i = np.divmod(np.arange(R * R), R)
    o = view.origin_np + np.outer((i + 0.5) * w, ex) + np.outer((j + 0.5) * w, ey)
    return o, np.broadcast_to(ez, o.shape).copy()


def _shifted(o, view, eps=1e-6):
    ex, ey, _ = view.axes_np
    return [o + eps * e for e in (ex, -ex, ey, -ey)]


def _unsure_layers(o, d, view, cull, expected):
    """Texels whose ray passes within 1e-6 of an edge of the L: their layers jump there."""
    z1, is_l, z2 = expected[:3]
    unsure = np.zeros(len(o), bool)
    for o2 in _shifted(o, view):
        s1, sl, s2 = _l_layers(o2, d, cull, view.far)[:3]
        unsure |= (np.abs(s1 - z1) > 1e-4) | (np.abs(s2 - z2) > 1e-4) | (sl != is_l)
    return unsure


def test_two_plates_layers_and_midpoint_dual_against_analytic_depths():
    """floating_plate with a 0.6 gap under a slanted light: z1, z2 and the first hit's shape of
    every texel against the plate's and the ground's depths along the texel's ray (float64),
    then midpoint and dual on receivers placed along texel rays at depths between the layers,
    against d <= (z1 + z2) / 2 and d <= z1 + min((z2 - z1) / 2, 4 texels) on those depths."""
    import drjit as dr
    import mitsuba as mi
    from dsm.scenes import load as scenes
    from dsm import schemes
    from dsm.maps import shadowmap
    from dsm.config.read import Length, parse
    from dsm.maps.lookup import visibility
    from dsm.maps.receiver import Receiver
    from dsm.maps.views import OrthographicView
    gap, R = 0.6, 160
    sd = scenes.load(parse(base_config(scene=[{"builtin": "floating_plate", "gap": gap}]), "<test>").scenes[0],
                     (32, 32))
    light = np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])
    view = OrthographicView(light, np.array([[-4.5, -4.5, 0], [4.5, 4.5, 0]]), sd.bbox, R)   # past the ground
    smap = shadowmap.build(sd.scene, view, {"z2"})
    scene = Scene64().quad("plate", [0, 0, gap], [0.75, 0, 0], [0, 0.75, 0]).quad("ground", [0, 0, 0], [4, 0, 0],
                                                                                  [0, 4, 0])
    o, d = _texel_rays(view)
    t_plate, t_ground = (scene.entry(k, o, d)[0] for k in range(2))
    on_plate, on_ground = np.isfinite(t_plate), np.isfinite(t_ground)
    amb = np.zeros(len(o), bool)            # texel rays within 1e-6 of an edge
    for o2 in _shifted(o, view):
        amb |= np.isfinite(scene.entry(0, o2, d)[0]) != on_plate
        amb |= np.isfinite(scene.entry(1, o2, d)[0]) != on_ground
    far = view.far
    z1 = np.where(on_plate, t_plate, np.where(on_ground, t_ground, far))
    z2 = np.where(on_plate & on_ground, t_ground, far)
    names = sd.shape_names
    shape = np.where(on_plate, names.index("plate"), np.where(on_ground, names.index("ground"), 0xFFFFFFFF))
    ok = ~amb
    assert on_plate[ok].sum() > 300 and (on_ground & ~on_plate)[ok].sum() > 1000 and (~on_ground)[ok].sum() > 0
    np.testing.assert_allclose(np.array(smap.z1)[ok], z1[ok], rtol=0, atol=1e-5)
    np.testing.assert_allclose(np.array(smap.z2)[ok], z2[ok], rtol=0, atol=1e-5)
    np.testing.assert_array_equal(np.array(smap.shape)[ok], shape[ok])
    # the gap along the slanted ray is gap / cos: the layers are that far apart under the plate
    both = ok & on_plate & on_ground
    np.testing.assert_allclose(z2[both] - z1[both], gap / -light[2], rtol=1e-9)

    # receivers on texel centre rays, at depth z1 + offset (no doubt about their texel)
    w = view.extent / R
    offsets = np.array([-0.05, 0.03, 0.18, 0.27, 0.37, 0.58])
    keep = np.flatnonzero(ok & on_ground)
    tex = np.repeat(keep, len(offsets))
    dep = z1[tex] + np.tile(offsets, len(keep))
    pts = o[tex] + dep[:, None] * d[tex]
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    rx = Receiver.make(view, p, dr.zeros(mi.Vector3f, len(pts)) + mi.Vector3f(0, 0, 1), sd.diagonal)
    mid_lit = dep <= 0.5 * (z1[tex] + z2[tex])
    dual_lit = dep <= z1[tex] + np.minimum(0.5 * (z2[tex] - z1[tex]), 4 * w)
    # every combination is there: both lit, midpoint lit but dual not, both shadowed
    assert (mid_lit & dual_lit).sum() > 100 and (mid_lit & ~dual_lit).sum() > 100 and (~mid_lit).sum() > 100
    mid = schemes.get("midpoint")
    v_mid = visibility(mid, mid.Params(), rx, smap)[0].numpy()
    dual = schemes.get("dual")
    v_dual = visibility(dual, dual.Params(z_offset=Length(4.0, "texel"), culling="none"), rx, smap)[0].numpy()
    np.testing.assert_array_equal(v_mid == 1.0, mid_lit)
    np.testing.assert_array_equal(v_dual == 1.0, dual_lit)


# The l_shape scene (Weiskopf & Ertl 2003, figure 5) for the tracer: an L-shaped prism, the union of two boxes
# (one closed mesh, no inner face), over the open ground.
L_BOXES = (([-1.0, -0.8, 0.5], [1.0, 0.8, 0.8]), ([0.7, -0.8, 0.8], [1.0, 0.8, 2.0]))


def _l_scene():
    scene = Scene64().quad("ground", [0, 0, 0], [4, 0, 0], [0, 4, 0])
    for lo, hi in L_BOXES:
        scene.box("l_shape", lo, hi)
    return scene


def _l_layers(o, d, cull_closed, far):
    """(z1, is_l, z2, cos1, cos2) along rays that start in front of everything (depth = t): the
    L's surfaces are where a ray enters and leaves the union of its boxes; with back_closed the
    L's back faces (where it leaves) are stepped over, the open ground never is. cos: |n . d| of
    the surface (1 where there is none)."""
    rows = np.arange(len(d))
    boxes = []
    for lo, hi in L_BOXES:
        lo, hi = np.asarray(lo), np.asarray(hi)
        t_in, t_out, axis_in = Scene64.slabs(lo, hi, o, d)
        with np.errstate(divide="ignore", invalid="ignore"):
            far_t = np.maximum((lo - o) / d, (hi - o) / d)
        far_t = np.where(d == 0, np.inf, far_t)
        axis_out = far_t.argmin(axis=1)
        boxes.append((t_in, t_out, np.abs(d[rows, axis_in]), np.abs(d[rows, axis_out])))
    (a_in, a_out, a_cin, a_cout), (b_in, b_out, b_cin, b_cout) = boxes
    a_ok, b_ok = a_in <= a_out, b_in <= b_out
    merged = a_ok & b_ok & (np.maximum(a_in, b_in) <= np.minimum(a_out, b_out) + 1e-12)
    inf = np.inf
    t_ground = _l_scene().entry(0, o, d)[0]
    events = [(np.where(a_ok & ~merged, a_in, inf), a_cin, True, False),
              (np.where(a_ok & ~merged, a_out, inf), a_cout, True, True),
              (np.where(b_ok & ~merged, b_in, inf), b_cin, True, False),
              (np.where(b_ok & ~merged, b_out, inf), b_cout, True, True),
              (np.where(merged, np.minimum(a_in, b_in), inf), np.where(a_in <= b_in, a_cin, b_cin), True, False),
              (np.where(merged, np.maximum(a_out, b_out), inf), np.where(a_out >= b_out, a_cout, b_cout), True, True),
              (t_ground, np.abs(d[:, 2]), False, False)]
    events = [e for e in events if not (cull_closed and e[3])]
    t = np.stack([e[0] for e in events], axis=1)
    cos = np.stack([np.broadcast_to(e[1], len(d)) for e in events], axis=1)
    order = np.argsort(t, axis=1)
    is_l = np.array([e[2] for e in events])[order]
    t, cos = np.take_along_axis(t, order, axis=1), np.take_along_axis(cos, order, axis=1)
    z1 = np.where(np.isfinite(t[:, 0]), t[:, 0], far)
    z2 = np.where(np.isfinite(t[:, 1]), t[:, 1], far)
    cos1 = np.where(np.isfinite(t[:, 0]), cos[:, 0], 1.0)
    cos2 = np.where(np.isfinite(t[:, 1]), cos[:, 1], 1.0)
    return z1, is_l[:, 0] & np.isfinite(t[:, 0]), z2, cos1, cos2


def assert_layers_match(smap, expected, ok, l_index):
    """z1, z2 and the first hit's shape of a map against the tracer's. A float32 hit is a few ulps
    off its surface, which moves it along a ray meeting the surface at |cos| = |n . d| by that
    over |cos|; z2 is found from a continuation ray that starts delta = 32 u (max|p| + extent)
    (dsm.scenes.spawn, under 1e-5 in these scenes) off the first hit along its normal, a ray parallel to
    the texel's, which moves it by at most delta (1 + 1 / |cos2|)."""
    z1, is_l, z2, cos1, cos2 = expected
    tol1 = 1e-6 + 4e-6 / cos1
    tol2 = 1e-6 + 4e-6 / cos2 + 1e-5 * (1 + 1 / cos2)
    for got, want, tol in ((np.array(smap.z1), z1, tol1), (np.array(smap.z2), z2, tol2)):
        bad = np.flatnonzero(ok & ~(np.abs(got - want) <= tol))
        assert bad.size == 0, (bad[:5], got[bad[:5]], want[bad[:5]], tol[bad[:5]])
    np.testing.assert_array_equal((np.array(smap.shape) == l_index)[ok], is_l[ok])


def _runner_view(sd, light, R):
    """The view the runner builds for a directional light: fitted to its receivers (from the
    G-buffer), so its texel frame is the runner's."""
    from dsm.scenes import gbuffer
    from dsm import pipeline
    W, H = (int(x) for x in sd.sensor.film().size())
    gb = gbuffer.cast(sd.scene, sd.sensor, W, H)
    setup = pipeline.light_setup(sd, gb, light, "0:directional")
    return pipeline.make_view(light, R, pipeline.points_np(setup.p), sd.bbox)


def _own_surface(view, z1, tex, p, n):
    """Per receiver (world ``p``, unit normal ``n``): the acne split's rule (docs/design.md, *The acne
    split*) in float64 on an orthographic view's analytic first layer ``z1`` (per texel; the far
    bound where nothing is hit) at each receiver's texel ``tex``; and how far from its threshold
    each receiver is, in texels."""
    R, w = view.resolution, view.extent / view.resolution
    ex, ey, ez = view.axes_np
    j, i = np.divmod(tex, R)
    centre = view.origin_np + np.outer((i + 0.5) * w, ex) + np.outer((j + 0.5) * w, ey)
    cos = n @ ez
    z_c = ((p - centre) * n).sum(1) / cos                # the receiver's plane on the centre ray
    e_rx = 0.5 * w * (np.abs(n @ ex) + np.abs(n @ ey)) / np.abs(cos)
    at = lambda a, b: z1[np.clip(b, 0, R - 1) * R + np.clip(a, 0, R - 1)]
    z = z1[tex]
    e_hit = 0.5 * (np.minimum(np.abs(at(i + 1, j) - z), np.abs(at(i - 1, j) - z))
                   + np.minimum(np.abs(at(i, j + 1) - z), np.abs(at(i, j - 1) - z)))
    margin = np.minimum(e_rx, e_hit) + w / 8 - np.abs(z - z_c)
    return (z < view.far) & (margin >= 0), np.abs(margin) / w


def _fig5_expected(sd, R, tr, light):
    """Per receiver pixel: the class (LIT, SHADOW, ACNE, PETERPAN) each (scheme, culling) of the
    experiment must give, from the tracer's hit points and V* and the L's analytic layers in the
    runner's own map frame; and which pixels are too close to a texel edge or a threshold to say."""
    from dsm.maps import shadowmap
    from dsm.truth.metrics import classify
    view = _runner_view(sd, light, R)
    ex, ey, ez = view.axes_np
    w = view.extent / R
    o, d = _texel_rays(view)
    closed = [name == "l_shape" for name in sd.shape_names]
    layers, maps = {}, {}
    for culling in ("none", "back_closed"):
        expected = _l_layers(o, d, culling == "back_closed", view.far)
        layers[culling] = (expected, _unsure_layers(o, d, view, culling == "back_closed", expected))
        modes = shadowmap.cull_modes_for(culling, closed) if culling != "none" else None
        maps[culling] = shadowmap.build(sd.scene, view, {"z2"}, culling, modes)
    rec = tr["receiver"]
    p = tr["p"][rec]
    q = p - view.origin_np
    u, v, dep = q @ ex / w, q @ ey / w, q @ ez
    i, j = np.clip(np.floor(u), 0, R - 1).astype(int), np.clip(np.floor(v), 0, R - 1).astype(int)
    tex = j * R + i
    near_edge = (np.abs(u - np.round(u)) < 1e-4) | (np.abs(v - np.round(v)) < 1e-4)
    rx_l = np.array([tr_name == "l_shape" for tr_name in (_l_scene().parts[k][0] for k in tr["part"][rec])])
    vstar = tr["vstar"][rec]
    out = {}
    # the experiment's tests (weiskopf_fig5.toml: dual z_offset = 0.3, constant bias = 0.3, world units)
    midpoint = lambda z1, z2: 0.5 * (z1 + z2)
    dual = lambda z1, z2: z1 + np.minimum(0.5 * (z2 - z1), 0.3)
    for (scheme, culling), thr_of in {("midpoint", "none"): midpoint, ("midpoint", "back_closed"): midpoint,
                                      ("dual", "none"): dual, ("dual", "back_closed"): dual,
                                      ("constant", "none"): lambda z1, z2: z1 + 0.3}.items():
        (z1, is_l, z2, _, _), amb = layers[culling]
        thr = thr_of(z1[tex], z2[tex])
        lit = dep <= thr
        unsure = tr["ambiguous"][rec] | amb[tex] | near_edge | (np.abs(dep - thr) < 1e-4)
        own, to_threshold = _own_surface(view, z1, tex, p, tr["n"][rec])
        unsure |= to_threshold < 1e-4
        out[(scheme, culling)] = dict(cls=classify(lit.astype(float), vstar), unsure=unsure, self_=own, on_l=rx_l)
    return out, maps, layers, rec


@pytest.mark.slow
def test_weiskopf_fig5_against_the_tracer(tmp_path):
    """Weiskopf & Ertl 2003, figure 5 as numbers. Every case's classes and counts against an independent
    computation: the tracer's receivers and V*, the L's layers along each texel ray in float64
    (entries and exits of the union of its boxes; back_closed drops its exits) and the schemes'
    tests on those depths. Then the paper's claims that the per-receiver metric can see on these
    checked numbers (receivers face the light, so the self-unshadowing of back-facing regions in
    its figure 5 (e) is outside every metric)."""
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    from dsm.truth.metrics import ACNE, OUTSIDE, PETERPAN, base_class
    toml = ROOT / "experiments" / "weiskopf_fig5.toml"
    res = dsm.run(toml, out=tmp_path / "w", report=False)
    assert res.run["n_failed"] == 0
    cfg = config.load(toml)
    sd = scenes.load(cfg.scenes[0], cfg.camera_resolution)
    light = sd.lights_for(cfg.lights)[0]
    tr = truth(_l_scene(), sd.sensor, light.direction)
    for R in (64, 128):
        expected, maps, layers, rec = _fig5_expected(sd, R, tr, light)
        for culling, smap in maps.items():          # the layers themselves
            expected_layers, amb = layers[culling]
            assert (~amb).sum() > 0.95 * len(amb)
            assert_layers_match(smap, expected_layers, ~amb, sd.shape_names.index("l_shape"))
        rows = {(r["scheme"], r["culling"]): r for r in res.rows if r["resolution"] == R}
        counts = {}
        for key, exp in expected.items():
            r = rows[key]
            assert_matches_truth(res, r, tr)              # its receivers and V*, pixel by pixel
            img = base_class(res.images[r["case"]].ravel()[rec])
            sure = ~exp["unsure"] & (img != OUTSIDE)
            bad = np.flatnonzero(sure & (img != exp["cls"]))
            assert bad.size == 0, (R, key, bad.size, "of", sure.sum(), img[bad[:5]], exp["cls"][bad[:5]])
            slack = int(exp["unsure"].sum())
            n_self = int(((exp["cls"] == ACNE) & exp["self_"]).sum())
            n_pp = int((exp["cls"] == PETERPAN).sum())
            assert abs(r["n_acne_self"] - n_self) <= slack, (R, key, r["n_acne_self"], n_self, slack)
            assert abs(r["n_peterpan"] - n_pp) <= slack, (R, key, r["n_peterpan"], n_pp, slack)
            # the L's acne on the L (the paper's self-shadowing of an object: by the acne split, much of
            # it is edge, one face of the L shadowing another at its silhouette)
            n_l = int(((exp["cls"] == ACNE) & exp["on_l"]).sum())
            counts[key] = (n_l, n_pp, slack)
        mid_n, mid_b = counts[("midpoint", "none")][0], counts[("midpoint", "back_closed")][0]
        # (b) midpoint shadows the L with itself at the L's silhouettes
        assert mid_n - counts[("midpoint", "none")][2] > 100, (R, counts)
        # (e) back-face culling of the closed L removes most of it
        assert mid_b < 0.6 * mid_n, (R, counts)
        # the open ground is never culled, so shadows on it are the same with or without culling
        assert rows[("dual", "back_closed")]["peterpan_rate"] == pytest.approx(
            rows[("dual", "none")]["peterpan_rate"], abs=0.01), R


def test_hit_shape_by_registry_id_equals_embree_shape_index():
    """cuda_ad_rgb's hits name their shape only by pointer (OptiX leaves ``shape_index`` 0): the
    registry-id table must give the index into scene.shapes() that Embree's ``shape_index`` gives,
    for meshes and analytic shapes in any order, and NO_SHAPE on a miss."""
    import mitsuba as mi
    from dsm.scenes import spawn
    xs = {"s": -6.0, "a": -3.0, "r": 0.0, "b": 3.0, "c": 6.0}      # one shape per x, each hit head-on
    scene = mi.load_dict({"type": "scene",
                          "s": {"type": "sphere", "center": [xs["s"], 0, 0], "radius": 1.0},
                          "a": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([xs["a"], 0, 0])},
                          "r": {"type": "rectangle"},
                          "b": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([xs["b"], 0, 0])},
                          "c": {"type": "disk", "to_world": mi.ScalarTransform4f().translate([xs["c"], 0, 0])}})
    order = [s.id() for s in scene.shapes()]
    names = list(xs) + ["miss"]
    ox = np.array([xs.get(k, 20.0) for k in names], np.float32)
    ray = mi.Ray3f(mi.Point3f(mi.Float(ox), 0.0, -5.0), mi.Vector3f(0, 0, 1))
    pi = scene.ray_intersect_preliminary(ray)
    valid = pi.is_valid()
    expected = np.array([order.index(k) if k != "miss" else spawn.NO_SHAPE for k in names], np.uint32)
    by_id = spawn.hit_shape(pi, valid, spawn.shape_table(scene, force=True)).numpy()
    assert np.array_equal(by_id, expected), (by_id, expected, order)
    if mi.variant().startswith("llvm"):            # Embree fills shape_index itself (OptiX leaves it 0)
        assert np.array_equal(spawn.hit_shape(pi, valid, None).numpy(), expected)


def test_a_hit_inside_an_instance_names_the_instance():
    """Two instances of one shape group: each hit names its own instance's index in
    scene.shapes() (Embree's shape_index gives the group's inner shape, OptiX's 0)."""
    import mitsuba as mi
    from dsm.scenes import spawn
    T = mi.ScalarTransform4f()
    scene = mi.load_dict({"type": "scene",
                          "grp": {"type": "shapegroup", "c": {"type": "cube"}},
                          "i1": {"type": "instance", "to_world": T.translate([-3, 0, 0]), "shapegroup": {"type": "ref", "id": "grp"}},
                          "i2": {"type": "instance", "to_world": T.translate([3, 0, 0]), "shapegroup": {"type": "ref", "id": "grp"}},
                          "r": {"type": "rectangle", "to_world": T.translate([0, 0, -2])}})
    order = [s.id() for s in scene.shapes()]
    names = ["i1", "i2", "r", "miss"]
    ox = np.array([-3.0, 3.0, 0.0, 20.0], np.float32)
    ray = mi.Ray3f(mi.Point3f(mi.Float(ox), 0.0, 5.0), mi.Vector3f(0, 0, -1))
    pi = scene.ray_intersect_preliminary(ray)
    got = spawn.hit_shape(pi, pi.is_valid(), spawn.shape_table(scene)).numpy()
    expected = np.array([order.index(k) if k in order else spawn.NO_SHAPE for k in names], np.uint32)
    assert np.array_equal(got, expected), (got, expected, order)


def test_a_continuation_through_a_sphere_is_not_a_rehit():
    """A sphere's far side is the same shape and prim_index (always 0) as its near side, yet a
    legitimate second layer: re-hits count on triangle meshes only."""
    from dsm.maps import shadowmap
    import mitsuba as mi
    scene = mi.load_dict({"type": "scene", "s": {"type": "sphere", "radius": 1.0},
                          "g": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -2]).scale(4)}})
    from dsm.config.read import LightSpec
    from dsm.pipeline import make_view
    pts = np.array([[-4, -4, -2], [4, 4, 1]], float)
    view = make_view(LightSpec("directional", direction=(0.0, 0.0, -1.0)), 64, pts, (pts[0], pts[1]))
    smap = shadowmap.build(scene, view, {"z2"})
    z1, z2 = np.array(smap.z1), np.array(smap.z2)
    ground = z1.max()                                       # texels beside the sphere see only the ground
    through = z2 < ground - 0.5                             # top then bottom of the sphere (it ends 1 above the ground)
    # the sphere (radius 1) covers about pi / (8/64)^2 = 201 texels of the 8 x 8 map
    assert 150 < through.sum() < 260, through.sum()
    assert smap.rehits == 0


def test_a_hit_from_the_triangle_tables_is_the_surface_interaction_bit_for_bit():
    """spawn.mesh_hit reads a triangle's vertices as one packet of the padded soup: its point and
    winding normal are Mitsuba's minimal surface interaction's bits, on two meshes (the hit's
    face offset in the soup), rays hitting both and missing both; the soup holds each
    triangle's nine coordinates at TRI_STRIDE, as numpy reads them from the meshes' buffers."""
    import drjit as dr
    import mitsuba as mi
    from dsm.scenes import spawn
    scene = mi.load_dict({"type": "scene", "a": {"type": "cube"},
                          "b": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0, 0, 4])
                                @ mi.ScalarTransform4f().rotate([1, 1, 0], 30)}})
    tables = spawn.shape_extents(scene)
    soup = np.asarray(tables.tri_pos.numpy()).reshape(-1, spawn.TRI_STRIDE)
    want = np.concatenate([np.asarray(s.vertex_positions_buffer(), np.float32).reshape(-1, 3)[
        np.asarray(s.faces_buffer(), np.int64).reshape(-1, 3)].reshape(-1, 9) for s in scene.shapes()])
    assert np.array_equal(soup[:, :9], want) and not soup[:, 9:].any()
    rng = np.random.default_rng(3)
    n = 4000
    o = rng.uniform([-2.5, -2.5, -3.0], [2.5, 2.5, -3.0], (n, 3)).astype(np.float32)
    d = rng.normal([0.0, 0.0, 1.0], 0.15, (n, 3)).astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(*o.T), dr.normalize(mi.Vector3f(*d.T)))
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    valid = pi.is_valid()
    shape = spawn.hit_shape(pi, valid, tables.by_id)
    p, nrm = spawn.mesh_hit(pi, shape, tables, valid)
    si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.Minimal, active=valid)
    hit = valid.numpy()
    assert 0.2 * n < hit.sum() < n                       # hits and misses both
    for mine, theirs in ((p, si.p), (nrm, si.n)):
        a, b = np.asarray(mine.numpy())[:, hit], np.asarray(theirs.numpy())[:, hit]      # (3, n)
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert set(np.unique(shape.numpy()[hit])) == {0, 1}
