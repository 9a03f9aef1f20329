"""Numbers a user can trust: a scheme's counts do not depend on what else runs."""
import pytest

from conftest import base_config

ONE_LAYER = [{"name": "none"}, {"name": "constant", "bias": "1 texel"}, {"name": "slope_scaled"},
             {"name": "normal_angle"}, {"name": "normal_offset"}, {"name": "receiver_plane"}, {"name": "adaptive"}]
LAYERED = [{"name": "midpoint", "culling": "none"}, {"name": "dual", "culling": "back_closed"},
           {"name": "second_depth"}, {"name": "midpoint", "culling": "back"}]
LIGHTS = [{"type": "directional", "direction": [-0.3, -0.2, -1.0]},
          {"type": "spot", "position": [-2.0, 1.5, 4.0], "target": [0.0, 0.0, 0.0], "cutoff": 45},
          {"type": "point", "position": [0.3, -0.2, 2.5]}]


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["plane_box", "l_shape", "room"])
def test_counts_do_not_depend_on_the_other_schemes(run_dict, scene):
    """Each scheme alone against the same scheme beside layered and culled schemes, on all five
    views: n_receivers, n_acne and n_peterpan are identical."""
    common = dict(scene=[{"builtin": scene}], light=LIGHTS, camera={"resolution": [64, 64]},
                  map={"resolution": 128, "view": ["paraboloid", "dual_paraboloid", "cube"]})
    together = run_dict(base_config(scheme=ONE_LAYER + LAYERED, **common), "together")
    views = {r["view"] for r in together.rows}
    assert views == {"orthographic", "perspective", "paraboloid", "dual_paraboloid", "cube"}
    key = lambda r: (r["light"], r["view"], r["scheme"], r["params"])
    both = {key(r): r for r in together.rows}
    # the one-layer schemes without any layered or culled map, and midpoint without culling
    for i, group in enumerate((ONE_LAYER, LAYERED[:1])):
        alone = run_dict(base_config(scheme=group, **common), f"alone{i}")
        assert len(alone.rows) == 5 * len(group)
        for r in alone.rows:
            other = both[key(r)]
            for col in ("n_receivers", "n_acne", "n_peterpan"):
                assert r[col] == other[col], (r["scheme"], r["view"], col, r[col], other[col])
    assert sum(r["n_receivers"] for r in together.rows) > 0


def test_inward_wound_room_is_not_culled(run_dict):
    """A spot above the closed room (wound inward): back_closed culling must not let the light
    through the ceiling, so dual with back_closed equals dual without culling, and every
    receiver inside is truly shadowed (the room is closed, the light outside)."""
    cfg = base_config(scene=[{"builtin": "room"}], camera={"resolution": [64, 64]}, map={"resolution": 128},
                      light=[{"type": "spot", "position": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "cutoff": 40}],
                      scheme=[{"name": "dual", "culling": ["none", "back_closed"]}])
    res = run_dict(cfg)
    a, b = res.rows
    assert a["n_receivers"] > 500 and a["n_gt_lit"] == 0 == b["n_gt_lit"]
    assert a["n_peterpan"] == b["n_peterpan"] == 0
    room = next(s for sc in res.run["scenes"] for s in sc["shapes"] if s["name"] == "room")
    assert room["closed"] is False and "inward" in room["why"]


def test_backface_lit_rate_orders_dual_before_midpoint_with_culling(run_dict):
    """Weiskopf & Ertl 2003, figure 5: with back faces of closed meshes culled, midpoint's second layer lies
    behind the L's far side, so the L's own back-facing pixels (attached shadow) read lit;
    dual's z_offset caps that. Back-facing pixels are not receivers: backface_lit_rate sees it."""
    cfg = base_config(scene=[{"builtin": "l_shape"}], camera={"resolution": [128, 128]}, map={"resolution": 512},
                      scheme=[{"name": "midpoint", "culling": "back_closed"},
                              {"name": "dual", "culling": "back_closed"}])
    res = run_dict(cfg)
    mid, dual = (res.where(scheme=s).rows[0] for s in ("midpoint", "dual"))
    assert mid["n_backfacing"] == dual["n_backfacing"] > 200
    assert mid["backface_lit_rate"] > 0.3                   # the L's far side reads lit
    assert dual["backface_lit_rate"] < 0.5 * mid["backface_lit_rate"]


def test_jitter_is_seeded_by_the_receiver_itself():
    """pcf_jitter4x4: a receiver's visibility does not change when the other receivers change."""
    import drjit as dr
    import mitsuba as mi
    import numpy as np
    from dsm.scenes import gbuffer, load as scenes, spec as scene_spec
    from dsm.maps import shadowmap
    from dsm.maps.lookup import visibility
    from dsm.maps.receiver import Receiver
    from dsm.pipeline import make_view, points_np as _points_np
    from dsm.schemes import constant
    from dsm.config.read import LightSpec, Length
    sd = scenes.load(scene_spec.parse_scene({"builtin": "plane_box"}, "<t>", "s", None)[0], (96, 96))
    gb = gbuffer.cast(sd.scene, sd.sensor, 96, 96)
    idx = np.flatnonzero(gb.hit).astype(np.uint32)
    p = dr.gather(mi.Point3f, gb.p, mi.UInt32(idx))
    n = dr.gather(mi.Vector3f, gb.n, mi.UInt32(idx))
    view = make_view(LightSpec("directional", direction=(-0.4, -0.3, -1.0)), 128, _points_np(p), sd.bbox)
    smap = shadowmap.build(sd.scene, view, set())
    prm = constant.Params(bias=Length(0.5, "texel"))
    full = visibility(constant, prm, Receiver.make(view, p, n, sd.diagonal), smap, "pcf_jitter4x4", 7)[0].numpy()
    half = mi.UInt32(np.arange(1, len(idx), 2, dtype=np.uint32))
    sub = visibility(constant, prm, Receiver.make(view, dr.gather(mi.Point3f, p, half), dr.gather(mi.Vector3f, n, half),
                                                  sd.diagonal), smap, "pcf_jitter4x4", 7)[0].numpy()
    partial = (full > 0) & (full < 1)
    assert partial[1::2].sum() > 50                    # receivers in a penumbra: the jitter matters there
    assert np.array_equal(sub, full[1::2])


def test_orthographic_map_keeps_a_margin_and_reads_lit_beyond_it():
    import mitsuba as mi
    import numpy as np
    from dsm.maps.views import MARGIN_TEXELS, OrthographicView
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3, 3, (500, 3)) + [2000.0, -1500.0, 10.0]
    view = OrthographicView((0.0, 0.0, -1.0), pts, (pts.min(0) - 1, pts.max(0) + 1), 256)
    u, v = view.project_on(mi.Point3f(*pts.T.astype(np.float32)))
    u, v = u.numpy(), v.numpy()
    # the fitted square's extreme points sit MARGIN_TEXELS texels inside the map (float64 expectation)
    assert min(u.min(), v.min()) == pytest.approx(MARGIN_TEXELS, abs=0.05)
    assert max(u.max(), v.max()) == pytest.approx(256 - MARGIN_TEXELS, abs=0.05)
    assert view.inside(mi.Point3f(*pts.T.astype(np.float32))).numpy().all()


def test_lookups_beyond_the_directional_map_find_no_caster(run_dict):
    """A normal offset far beyond the map reads no caster: every receiver lit (acne 0, all the
    truly shadowed ones peter-panned), not the clamped border texel's depth."""
    cfg = base_config(scene=[{"builtin": "floating_plate"}], camera={"resolution": [96, 96]}, map={"resolution": 64},
                      scheme=[{"name": "normal_offset", "offset": "500 texel"}])
    r = run_dict(cfg).rows[0]
    assert r["n_gt_shadowed"] > 100
    assert r["n_acne"] == 0 and r["peterpan_rate"] == 1.0


def test_plane_hit_defined_where_the_ray_misses_the_plane():
    """View.plane_hit: analytic depth where the texel ray meets the plane; +inf and not met where
    the plane is parallel to the ray or crosses it behind the light."""
    import mitsuba as mi
    import numpy as np
    from dsm.maps.views import PerspectiveView
    view = PerspectiveView((0.0, 0.0, 5.0), (0.0, 0.0, -1.0), 30.0, (np.array([-4.0, -4, 0]), np.array([4.0, 4, 1])), 64)
    u, v = mi.Float(32.0), mi.Float(32.0)       # the centre: the ray straight down the axis
    cases = [((0, 0, 1.0), (0, 0, 1.0), True, 4.0),        # the plane z = 1: depth 4 along the axis
             ((0, 0, 1.0), (1.0, 0, 0), False, np.inf),    # a vertical plane containing the ray: parallel
             ((0, 0, 7.0), (0, 0, 1.0), False, np.inf)]    # the plane z = 7: above (behind) the light
    for p0, n, met_expected, depth_expected in cases:
        depth, met = view.plane_hit(u, v, mi.Point3f(*p0), mi.Vector3f(*n))
        assert bool(met.numpy()[0]) is met_expected
        assert depth.numpy()[0] == pytest.approx(depth_expected)


def test_ndc24_cube_compares_face_axis_depth(run_dict):
    """A cube map in ndc24 stores each face's axis depth, as a rasterizer does: every point of a
    plane perpendicular to the -z face's axis has axis depth 2.5 exactly, so no bias is needed;
    in float32 the cube stores the Euclidean distance, which varies within a texel (acne)."""
    cfg = base_config(scene=[{"builtin": "plane", "tilt": 0.0}], camera={"resolution": [96, 96]},
                      light=[{"type": "point", "position": [0.3, -0.2, 2.5]}],
                      map={"resolution": 128, "view": "cube", "format": ["float32", "ndc24"]},
                      scheme=[{"name": "none"}])
    res = run_dict(cfg)
    f32, ndc = (res.where(format=f).rows[0] for f in ("float32", "ndc24"))
    assert ndc["n_receivers"] == f32["n_receivers"] > 3000
    assert ndc["n_acne"] == 0
    assert f32["acne_rate"] > 0.2


@pytest.mark.slow
@pytest.mark.parametrize("translate", [[1e4, 0, 0], [0, 1e4, 0], [0, 0, 1e4], [2000, 1500, 100]])
def test_far_from_the_origin_the_counts_hold(run_dict, dsm_results, translate):
    """The floating plate moved up to 1e4 along each axis: a bias far above float32's step there
    (0.05 under a 0.2 gap; the step at 1e4 is 0.001) gives the rates of the scene at the origin."""
    def config(t):
        return base_config(scene=[{"builtin": "floating_plate", "translate": t}], camera={"resolution": [128, 128]},
                           map={"resolution": 512}, scheme=[{"name": "constant", "bias": [0.05, "2 texel"]}])
    # the scene at the origin is the same run for every translation: run once per session
    here, there = dsm_results(config([0, 0, 0])).rows, run_dict(config(translate), "far").rows
    assert here[0]["n_gt_shadowed"] > 150
    for a, b in zip(here, there):
        assert a["params"] == b["params"]
        assert abs(a["n_gt_shadowed"] - b["n_gt_shadowed"]) <= 0.01 * a["n_gt_shadowed"]
        for col in ("acne_rate", "peterpan_rate", "error_rate"):
            assert abs(a[col] - b[col]) <= 0.01, (translate, a["params"], col, a[col], b[col])


@pytest.mark.slow
def test_the_map_wavefront_gives_each_case_what_its_own_lookups_give(run_dict):
    """The runner evaluates every depth case's attached-shadow lookup and plane-fallback mask of a map
    in one wavefront; each case's backface_lit_rate and n_plane_fallback must be what the pipeline's
    stages give for that case alone (the per-case path, stage by stage: a second computation)."""
    import dsm.pipeline as pl
    schemes = [{"name": "receiver_plane"}, {"name": "adaptive"}, {"name": "constant", "bias": ["1 texel", "3 texel"]},
               {"name": "normal_offset"}]
    cfg = base_config(scene=[{"builtin": "l_shape"}], camera={"resolution": [64, 64]},
                      map={"resolution": 64, "filter": ["nearest", "pcf_jitter4x4"]}, scheme=schemes)
    res = run_dict(cfg)
    sd = pl.load_scene(pl.scene_spec({"builtin": "l_shape"}), (64, 64))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, sd.own_lights[0], "0:directional")
    view = pl.make_view(setup.light, 64, pl.points_np(setup.p), sd.bbox)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool))
    specs = [s for t in schemes for s in pl.scheme_specs(t)]
    smap = pl.store(pl.build_map(sd.scene, view, pl.needs_of(specs)), "float32")
    rx = pl.receivers(smap.view, setup, sd.diagonal)
    bp, bn = setup.backfacing_inside(view)
    back = pl.Receiver.make(smap.view, bp, bn, sd.diagonal, setup.camera)
    assert len(res.rows) == 10
    for row in res.rows:
        spec = next(s for s in specs if s.name == row["scheme"] and s.label == row["params"])
        v_back = pl.visibility(spec, back, smap, row["filter"], 7)[0].numpy()
        assert row["n_backfacing"] == v_back.size > 50
        assert row["backface_lit_rate"] == float((v_back >= 0.5).mean()), (row["scheme"], row["filter"])
        want = pl.plane_fallbacks(spec, rx, smap) if spec.name in ("receiver_plane", "adaptive") else None
        assert (row["n_plane_fallback"] if want is not None else None) == want
