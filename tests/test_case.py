"""A case as a value (dsm.case): the evaluation's counts, classes and leak split against numpy
on its own V and V*; the wavefront's lookups and a lookup here give the same case; a motion
path that does not move counts each frame as the still case; a context's measures are checked."""
import numpy as np
import pytest

from conftest import base_config


def _context(measures=frozenset(), fmt="float32"):
    import dsm.pipeline as pl
    from dsm.case import MapContext, Where
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (64, 64))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, pl.LightSpec("directional", direction=(-0.4, -0.3, -1.0)), "sun")
    view = pl.make_view(setup.light, 64, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view, ())
    stored = {fmt: pl.store(smap, fmt)}
    rx = {fmt: pl.receivers(stored[fmt].view, setup, sd.diagonal)}
    where = Where(sd.label, "sun", view.kind, 64, view.n_texels, "none")
    return MapContext(where, sd, gb, setup, view, smap, stored, rx, 7, 1, frozenset(measures), leak_texels=2.0)


@pytest.mark.slow
@pytest.mark.parametrize("bias", [0.0, 0.02])
def test_evaluated_counts_and_class_image_match_numpy_on_its_own_v(bias):
    import dsm.pipeline as pl
    from dsm.case import Case, evaluate
    from dsm.truth import metrics
    ctx = _context({"leak"})
    spec = pl.scheme_spec({"name": "constant", "bias": bias})
    res = evaluate(ctx, Case("0001", spec, "nearest", "float32"))
    v, v_star = np.asarray(res.v, np.float64), np.asarray(ctx.setup.v_star, bool)
    # the lookup alone on the same receivers: the same bits
    v_alone = pl.visibility(spec, ctx.receivers["float32"], ctx.stored["float32"])[0].numpy()
    assert np.array_equal(v, v_alone)
    acne, peter = v_star & (v < 0.5), ~v_star & (v >= 0.5)
    m = res.measured
    assert m["n_receivers"] == v.size == len(ctx.setup.pixels)
    assert (m["n_acne"], m["n_peterpan"], m["n_gt_lit"]) == (acne.sum(), peter.sum(), v_star.sum())
    assert m["error_rate"] == pytest.approx((acne.sum() + peter.sum()) / v.size, rel=1e-12)
    assert m["n_peterpan_edge"] + m["n_leak"] == m["n_peterpan"]
    # the class image: every receiver pixel carries its class, and nothing else is drawn
    classes = res.classes.ravel()
    assert res.classes.shape == (64, 64)
    assert np.count_nonzero(classes[ctx.setup.pixels] == metrics.ACNE) == acne.sum()
    assert np.count_nonzero(np.isin(classes, (metrics.PETERPAN, metrics.LEAK))) == peter.sum()
    assert not np.delete(classes, ctx.setup.pixels).any()
    if bias == 0.0:
        assert acne.sum() > 0            # the unbiased lookup has acne here: the counts above are not all zero


def test_the_wavefront_and_a_lookup_of_its_own_give_the_same_case():
    import dsm.pipeline as pl
    from dsm.case import Case, evaluate
    from dsm.experiment import wavefront
    ctx = _context({"attached"})
    case = Case("0001", pl.scheme_spec({"name": "receiver_plane"}), "pcf_bilinear", "float32")
    looked, _ = wavefront.run([case.lookup_key], ctx.stored, ctx.receivers, {"float32": None}, ctx.seed, 1)
    alone, waved = evaluate(ctx, case), evaluate(ctx, case, looked[case.lookup_key])
    assert np.array_equal(alone.v, waved.v) and np.array_equal(alone.classes, waved.classes)
    assert alone.measured.keys() == waved.measured.keys()
    for k, a in alone.measured.items():
        b = waved.measured[k]
        assert a == b or (a != a and b != b), k


def test_a_context_refuses_a_measure_it_does_not_know():
    with pytest.raises(ValueError, match="unknown measures.*'contact'"):
        _context({"contacts"})


@pytest.mark.slow
def test_a_motion_path_that_does_not_move_counts_each_frame_as_the_still_case(run_dict):
    """Three frames of a still camera and light: a motion case's counts are three times the still
    run's and its rates the same (motion's frame loop and the runner evaluate cases alike). No
    unbiased scheme: a frame's camera is rebuilt from its pose, and the last bits of its hits
    move the unbiased lookup's self-shadowing noise (3 of 682 acne pixels here)."""
    kw = dict(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]}, map={"resolution": 64},
              scheme=[{"name": "constant", "bias": 0.02}, {"name": "normal_offset"}, {"name": "receiver_plane"}])
    still = run_dict(base_config(**kw), "still")
    moved = run_dict(base_config(**kw, motion=[{"frames": 3, "points": 200}]), "motion")
    assert len(still.rows) == len(moved.rows) == 3
    for a, b in zip(still.rows, moved.rows):
        assert (a["scheme"], a["params"]) == (b["scheme"], b["params"])
        for k in ("n_receivers", "n_gt_lit", "n_acne", "n_peterpan"):
            assert b[k] == 3 * a[k], (a["scheme"], k)
        for k in ("acne_rate", "peterpan_rate", "error_rate"):
            assert b[k] == pytest.approx(a[k], rel=1e-12, nan_ok=True), (a["scheme"], k)
    assert still.rows[0]["n_acne"] > 100        # the small constant bias has acne: a count that could differ
