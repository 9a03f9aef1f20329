"""Moving casters under [[motion]] and the maps' cache policies (dsm.experiment.casters, .cache).

Known answers: with nothing moving every policy gives the same numbers as a path without
casters; a box sliding over a plane under a sun with ``static``: its ghosts are the receivers in
the box's shadow at frame 0 but not at frame k, its missing shadows the converse, both counted
here by a float64 ray-box test (numpy) within the receivers one texel from the outlines."""
import csv
import math

import numpy as np
import pytest

from conftest import base_config

SUN = [-1.0, -0.3, -0.8]
SLIDE = [0.0, 1.2, 0.0]           # the box's whole translation over the frames (world units)
FRAMES = 3
TIMES = {"build_ms", "build_first_ms", "lookup_ms", "build_compile_ms", "build_peak_mb", "lookup_compile_ms",
         "lookup_kernels_compiled", "reference_ms", "moments_ms", "frame_build_ms", "fit_ms", "case"}


def _config(motion, light=None, camera=48, resolution=64):
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [camera, camera]},
                       map={"resolution": resolution},
                       light=light or [{"type": "directional", "direction": SUN}],
                       scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}], motion=motion)


def _frames(out):
    with open(out / "frames.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _metrics(out):
    with open(out / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _without_times(rows, drop=()):
    return [{k: v for k, v in r.items() if k not in TIMES and k not in drop} for r in rows]


def test_translations_linear_and_keyframes_by_hand():
    """A linear path reaches ``offset`` at the last frame; keyframes are spread evenly and interpolated."""
    from dsm.core.types import CasterPath
    from dsm.experiment.casters import translations
    out = translations([CasterPath("a", offset=(2.0, 0.0, 0.0)),
                        CasterPath("b", keys=((0.0, 0.0, 0.0), (0.0, 4.0, 0.0), (0.0, 4.0, 2.0)))], 5, 0.5)
    assert np.allclose(out[:, 0, 0], [0.0, 0.25, 0.5, 0.75, 1.0])
    assert np.allclose(out[:, 1], [[0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 2, 0.5], [0, 2, 1]])
    from dsm.experiment.casters import rotation, turns
    assert np.allclose(turns([CasterPath("a", angle=90.0)], 4)[:, 0], [0, 30, 60, 90])
    assert np.allclose(rotation((0, 0, 2), 90.0) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])     # right-handed, as Mitsuba's
    assert np.allclose(rotation((1, 1, 1), 120.0) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def test_kept_spawn_tables_of_a_moved_geometry_are_a_fresh_computations():
    """Two paths moving the box alike share each frame's spawn tables (computed once), bit for bit a fresh
    computation on the scene as placed; a turn that differs is its own geometry; with no budget nothing is kept."""
    from dsm import pipeline
    from dsm.config import read as config
    from dsm.core.types import CasterPath
    from dsm.experiment.casters import KeptTables, Mover
    from dsm.scenes import load as scenes
    sd = scenes.load(config.parse(_config([]), "<test>").scenes[0], (16, 16))
    calls = []

    def counted(scene):
        calls.append(1)
        return pipeline.spawn_extents(scene)

    def arrays(tables):
        return [np.asarray(x) for x in (*tables, tables.tri_pos, tables.face_offset)]
    for budget, computed in ((1 << 30, 4), (0, 6)):
        kept, calls[:] = KeptTables(counted, budget), []
        paths = [Mover(sd, [CasterPath("box", offset=(0.0, 1.0, 0.0), angle=a)], 3, "<test>", "motion")
                 for a in (20.0, 20.0, 30.0)]
        for mover in paths:
            for t in (1, 2):
                mover.place(t)
                got, fresh = arrays(kept.at(mover.signature(t), sd.scene)), arrays(pipeline.spawn_extents(sd.scene))
                assert all(np.array_equal(a, b) for a, b in zip(got, fresh))
            mover.restore()
        # frames 1 and 2 of the first path, then the third's (a different turn): the second path's are the first's
        assert len(calls) == computed
    assert paths[0].signature(1) == paths[1].signature(1) != paths[2].signature(1)


@pytest.mark.slow
def test_nothing_moving_every_policy_gives_the_same_numbers(run_dict):
    """A camera dolly and a moving spot, with no caster, a caster whose offset is zero, under
    ``none`` and ``static``: every count and rate of metrics.csv and frames.csv is the same, and
    no frame has a ghost or a missing shadow."""
    spot = [{"type": "spot", "position": [-2.0, -1.0, 3.0], "target": [0.0, 0.0, 0.0], "cutoff": 45}]
    paths = [{"frames": 3, "points": 300, "camera": "dolly", "offset": [0.0, 0.4, 0.0], "label": "p"},
             {"frames": 3, "points": 300, "light": "move", "light_offset": [0.0, 1.0, 0.0], "label": "q"}]
    variants = {"plain": {}, "none": {"cache": "none", "casters": [{"shape": "box", "offset": [0.0, 0.0, 0.0]}]},
                "static": {"cache": "static"}, "stagger:2": {"cache": "stagger:2"}}
    runs = {}
    for name, extra in variants.items():
        res = run_dict(_config([{**p, **extra} for p in paths], light=spot), name=name.replace(":", "_"))
        casts = ("maps_built", "map_built", "recast_fraction")      # stagger casts on time, the others when needed
        runs[name] = (_without_times(_metrics(res.out), ("cache",)), _without_times(_frames(res.out), ("cache",)),
                      _without_times(_metrics(res.out), ("cache",) + casts),
                      _without_times(_frames(res.out), ("cache",) + casts))
    assert runs["plain"][:2] == runs["none"][:2] == runs["static"][:2]
    assert runs["plain"][2:] == runs["stagger:2"][2:]
    frames = runs["plain"][1]
    assert frames and all(f["n_ghost"] == "0" and f["n_missing"] == "0" for f in frames)
    assert any(f["map_built"] == "True" for f in frames if int(f["frame"]) > 0)     # the light's views did change


def _box_hits(p, d, lo, hi):
    """Whether the ray p + t d, t > 0, meets the box [lo, hi] (float64 slabs; a start inside hits)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - p) / d, (hi - p) / d
    tn = np.nanmax(np.minimum(t1, t2), axis=1)
    tf = np.nanmin(np.maximum(t1, t2), axis=1)
    return (tf > 1e-9) & (tf >= tn)


def _expected(setup_p, box, offset, grow):
    """(certainly inside the shadow of the box moved by ``offset``, inside it give or take ``grow``
    across the box's vertical sides): per receiver, toward the sun."""
    d = -np.asarray(SUN, float) / np.linalg.norm(SUN)
    d = np.broadcast_to(d, setup_p.shape)
    lo, hi = box[0] + offset, box[1] + offset
    g = np.array([grow, grow, 0.0])
    return _box_hits(setup_p, d, lo + g, hi - g), _box_hits(setup_p, d, lo - g, hi + g)


def _receivers_at(offset, camera):
    """The receivers' world positions with the box moved by ``offset`` (moved here through
    mi.traverse, independently of dsm.experiment.casters), and the box's loaded bounds."""
    import mitsuba as mi
    import dsm.pipeline as pl
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (camera, camera))
    params = mi.traverse(sd.scene)
    v = np.asarray(params["box.vertex_positions"], np.float64).reshape(-1, 3)
    box = (v.min(0), v.max(0))
    params["box.vertex_positions"] = mi.Float((v + offset).astype(np.float32).ravel())
    params.update()
    from dsm.core.types import LightSpec
    light = LightSpec("directional", direction=tuple(SUN))
    setup = pl.light_setup(sd, pl.gbuffer(sd), light, "sun")
    return pl.points_np(setup.p), box


def test_static_cache_ghosts_and_missing_shadows_of_a_sliding_box(run_dict, dsm_results):
    """``static``: the map of frame 0 kept while the box slides; at frame k the ghosts are the
    receivers in the frame-0 shadow outside the frame-k shadow, the missing the converse (numpy's
    ray-box count, within the receivers one texel from either outline); ``none`` has neither."""
    motion = {"frames": FRAMES, "points": 200, "casters": [{"shape": "box", "offset": SLIDE}]}
    camera, resolution = 128, 1024      # the outlines' one-texel band well narrower than the ghost
    res_static = run_dict(_config([{**motion, "cache": "static"}], camera=camera, resolution=resolution),
                          name="static")
    res_none = dsm_results(_config([{**motion, "cache": "none"}]))      # the sliding box under none: run once
    frames = _frames(res_static.out)
    texel = 8.0 * math.sqrt(2.0) / resolution     # a bound on a texel's width: the ground's diagonal over R
    grow = 1.0 * texel / (-SUN[2] / np.linalg.norm(SUN))     # one texel, as it lies on the ground
    _, box = _receivers_at(np.zeros(3), camera)
    checked = 0
    for k in range(1, FRAMES):
        off = np.asarray(SLIDE) * k / (FRAMES - 1)
        p, _ = _receivers_at(off, camera)
        in0, maybe0 = _expected(p, box, np.zeros(3), grow)
        ink, maybek = _expected(p, box, off, grow)
        on_box_k = np.all((p >= box[0] + off - 1e-4) & (p <= box[1] + off + 1e-4), axis=1)
        ink, maybek = ink & ~on_box_k, maybek & ~on_box_k      # a convex box does not shadow its lit faces
        band = (in0 != maybe0) | (ink != maybek)
        ghost, missing = in0 & ~maybek, ink & ~maybe0
        rows = [f for f in frames if int(f["frame"]) == k]
        assert rows and all(int(f["n_receivers"]) == len(p) for f in rows)
        for f in rows:
            assert ghost.sum() >= 100 and missing.sum() >= 40 and band.sum() < ghost.sum()
            # between the receivers certainly in it and those in it give or take a texel
            assert ghost.sum() <= int(f["n_ghost"]) <= (maybe0 & ~ink).sum(), (k, f["n_ghost"], ghost.sum())
            assert missing.sum() <= int(f["n_missing"]) <= (maybek & ~in0).sum(), (k, f["n_missing"], missing.sum())
            assert f["map_built"] == "False" and float(f["recast_fraction"]) == 0.0
            checked += 1
    assert checked == 2 * (FRAMES - 1)
    none = _frames(res_none.out)
    assert all(f["n_ghost"] == "0" and f["n_missing"] == "0" and f["map_built"] == "True" for f in none)
    assert all(float(f["recast_fraction"]) == 1.0 for f in none)


@pytest.mark.slow
def test_a_caster_back_where_it_was_leaves_a_static_map_right(run_dict):
    """Keyframes out and back: under ``static`` the last frame's kept map is right again (no ghost,
    no missing shadow), the middle frame's is not; ``none`` casts every frame whose casters moved."""
    motion = {"frames": 3, "points": 200, "casters": [{"shape": "box", "keys": [[0, 0, 0], [0.0, 1.2, 0.0],
                                                                                 [0, 0, 0]]}]}
    static = _frames(run_dict(_config([{**motion, "cache": "static"}]), name="static").out)
    none = _frames(run_dict(_config([{**motion, "cache": "none"}]), name="none").out)
    by = lambda rows, k: [f for f in rows if int(f["frame"]) == k]
    assert all(int(f["n_ghost"]) > 0 and int(f["n_missing"]) > 0 for f in by(static, 1))
    assert all(f["n_ghost"] == "0" and f["n_missing"] == "0" for f in by(static, 2))
    assert [f["map_built"] for f in by(static, 2)] == ["False"] * 2
    assert all(f["map_built"] == "True" for f in none)
    # the map at frame 2 under none is cast again on the loaded geometry: the same counts as frame 0
    keep = ("n_receivers", "acne_rate", "peterpan_rate", "error_rate")
    assert [{k: f[k] for k in keep} for f in by(none, 2)] == [{k: f[k] for k in keep} for f in by(none, 0)]


def test_stagger_casts_every_n_frames_and_stagger_one_is_none(run_dict):
    """The sliding box under ``stagger:2``: cast at frames 0, 2, 4, its ghosts only at the odd
    frames, and those equal to ``static``'s at frame 1; ``stagger:1`` gives ``none``'s numbers."""
    motion = {"frames": 5, "points": 200, "casters": [{"shape": "box", "offset": SLIDE}]}
    outs = {c: run_dict(_config([{**motion, "cache": c}]), name=c.replace(":", "_")).out
            for c in ("none", "static", "stagger:1", "stagger:2")}
    runs = {c: _frames(out) for c, out in outs.items()}
    stagger = runs["stagger:2"]
    assert [f["map_built"] for f in stagger if f["scheme"] == "constant"] == ["True", "False"] * 2 + ["True"]
    rows = _metrics(outs["stagger:2"])          # the same run's per-case rows (a second run only repeated it)
    for r in rows:            # per case: the mean over the frames, the worst frame, the mean texels re-cast
        mine = [f for f in stagger if f["scheme"] == r["scheme"]]
        rates = [float(f["ghost_rate"]) for f in mine]
        assert r["cache"] == "stagger:2" and float(r["recast_fraction"]) == pytest.approx(3 / 5, rel=1e-5)
        assert float(r["ghost_rate"]) == pytest.approx(np.mean(rates), rel=1e-5)
        assert float(r["ghost_rate_worst"]) == pytest.approx(max(rates), rel=1e-5) and max(rates) > 0
    assert all((int(f["n_ghost"]) > 0) == (int(f["frame"]) % 2 == 1) for f in stagger)
    one = lambda rows: [(f["frame"], f["scheme"], f["n_ghost"], f["n_missing"]) for f in rows if f["frame"] == "1"]
    assert one(stagger) == one(runs["static"])
    assert _without_times(runs["stagger:1"], ("cache",)) == _without_times(runs["none"], ("cache",))


def test_moving_caster_config_errors_name_the_key():
    """A caster without a path, with both paths, or naming no shape of the scene: one line naming the key."""
    import dsm
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    for casters, key in (([{"shape": "box"}], "motion[0].casters[0]"),
                         ([{"shape": "box", "offset": [1, 0, 0], "keys": [[0, 0, 0], [1, 0, 0]]}], "motion[0].casters[0]"),
                         ([{"shape": "box", "keys": [[0, 0, 0]]}], "motion[0].casters[0].keys"),
                         ([{"shape": "box", "offset": [1, 0]}], "motion[0].casters[0].offset"),
                         ([{"shape": "box", "offset": [1, 0, 0], "speed": 1}], "motion[0].casters[0].speed"),
                         ([{"shape": "box", "angle": 10, "axis": [0, 0, 0]}], "motion[0].casters[0].axis"),
                         ([{"shape": "box", "angle": "ten"}], "motion[0].casters[0].angle"),
                         ([{"shape": "box", "angle": 5, "static": 1}], "motion[0].casters[0].static")):
        with pytest.raises(ConfigError) as e:
            config.parse(base_config(motion=[{"casters": casters}]), "t.toml")
        assert e.value.key == key, (casters, e.value)
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(motion=[{"cache": "lazy"}]), "t.toml")
    assert e.value.key == "motion[0].cache" and list(e.value.choices) == ["none", "static", "stagger:N", "invalidate"]
    for bad in ("stagger:0", "stagger:x", "stagger:"):
        with pytest.raises(ConfigError) as e:
            config.parse(base_config(motion=[{"cache": bad}]), "t.toml")
        assert e.value.key == "motion[0].cache" and bad in str(e.value)
    assert config.parse(base_config(motion=[{"cache": "stagger:03"}]), "t.toml").motion[0].cache == "stagger:3"
    with pytest.raises(ConfigError) as e:
        dsm.run(_config([{"frames": 2, "points": 10, "casters": [{"shape": "teapot", "offset": [1, 0, 0]}]}]), report=False)
    assert e.value.key == "motion[0].casters[0].shape" and list(e.value.choices) == ["ground", "box"]


@pytest.mark.slow
@pytest.mark.parametrize("path", ["slide", "turn"])
def test_a_moved_mesh_gives_the_numbers_of_a_file_with_the_mesh_there(run_dict, tmp_path, path):
    """A mesh scene (Mitsuba XML of two OBJ files): the box moved by the path under ``none`` (slid
    by 1 along y, or turned by 30 degrees about z through its centre) gives at its last frame every
    count of the first frame of a scene whose OBJ holds the box already there (exact visibility,
    receivers and map per frame follow the geometry)."""
    from test_acne_surface import _box, _obj, _xml
    ground = (np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    (tmp_path / "ground.obj").write_text(_obj([ground]))
    box = _box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])
    (tmp_path / "box.obj").write_text(_obj([box]))
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    there = box[0] + [0.0, 1.0, 0.0] if path == "slide" else box[0] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    caster = {"shape": "s1", "offset": [0.0, 1.0, 0.0]} if path == "slide" else {"shape": "s1", "angle": 30.0}
    (tmp_path / "moved.obj").write_text(_obj([(there, box[1])]))
    (tmp_path / "a.xml").write_text(_xml(["ground.obj", "box.obj"]))
    (tmp_path / "b.xml").write_text(_xml(["ground.obj", "moved.obj"]))
    light = [{"type": "directional", "direction": SUN}]
    base = dict(camera={"resolution": [48, 48]}, map={"resolution": 64}, light=light,
                scheme=[{"name": "constant", "bias": "1 texel"}, {"name": "normal_offset"}])
    moving = _frames(run_dict(base_config(scene=[{"file": str(tmp_path / "a.xml")}], **base, motion=[
        {"frames": 2, "points": 200, "casters": [caster]}]), name="a").out)
    there = _frames(run_dict(base_config(scene=[{"file": str(tmp_path / "b.xml")}], **base,
                                         motion=[{"frames": 2, "points": 200}]), name="b").out)
    keep = ("n_receivers", "acne_rate", "peterpan_rate", "error_rate")
    last = [{k: f[k] for k in keep} for f in moving if f["frame"] == "1"]
    first = [{k: f[k] for k in keep} for f in moving if f["frame"] == "0"]
    assert last == [{k: f[k] for k in keep} for f in there if f["frame"] == "0"]
    assert last != first                                  # the box did move


def _in_hull(points, corners):
    """Whether each 2-D point lies inside the convex hull of ``corners`` (numpy: monotone chain, then
    every edge's side)."""
    pts = sorted(map(tuple, np.round(corners, 12)))
    cross = lambda o, a, b: (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = np.array(lower[:-1] + upper[:-1])
    ok = np.ones(len(points), bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        ok &= (b[0] - a[0]) * (points[:, 1] - a[1]) - (b[1] - a[1]) * (points[:, 0] - a[0]) >= 0
    return ok


def test_invalidate_recasts_the_texels_the_box_covers_and_equals_none(run_dict, dsm_results):
    """``invalidate``: every count and rate of ``none`` and no ghost; the texels re-cast at frame k
    are those whose centres fall inside the sun's projection of the box at frame k - 1 or at k (the
    convex hulls of its projected corners, counted here), a small fraction of the map."""
    import dsm.pipeline as pl
    from dsm.core.types import LightSpec
    motion = {"frames": FRAMES, "points": 200, "casters": [{"shape": "box", "offset": SLIDE}]}
    inv = _frames(run_dict(_config([{**motion, "cache": "invalidate"}]), name="invalidate").out)
    none = _frames(dsm_results(_config([{**motion, "cache": "none"}])).out)
    keep = ("frame", "scheme", "n_receivers", "acne_rate", "peterpan_rate", "error_rate", "n_ghost", "n_missing")
    assert [{k: f[k] for k in keep} for f in inv] == [{k: f[k] for k in keep} for f in none]
    assert all(f["n_ghost"] == "0" and f["n_missing"] == "0" for f in inv)
    p0, box = _receivers_at(np.zeros(3), 48)
    light = LightSpec("directional", direction=tuple(SUN))
    bbox = (np.array([-4.0, -4.0, 0.0]), np.array([4.0, 4.0, 1.0]))    # the ground holds the box's whole path
    view = pl.make_view(light, 64, p0, bbox)
    R = view.resolution
    jj, ii = np.mgrid[0:R, 0:R]
    centres = np.stack([ii.ravel() + 0.5, jj.ravel() + 0.5], axis=1)
    corners = np.array([[box[i >> k & 1][k] for k in range(3)] for i in range(8)])
    uv = lambda pts: np.stack([np.asarray(c.numpy(), float) for c in view.project_on(mi_points(pts))], axis=1)
    for k in range(1, FRAMES):
        was, now = (np.asarray(SLIDE) * j / (FRAMES - 1) for j in (k - 1, k))
        expected = _in_hull(centres, uv(corners + was)) | _in_hull(centres, uv(corners + now))
        texels = {round(float(f["recast_fraction"]) * R ** 2) for f in inv if int(f["frame"]) == k}   # CSV: 6 digits
        assert texels == {int(expected.sum())}, (k, texels, expected.sum())
        assert 0.005 < expected.mean() < 0.2
        assert all(f["map_built"] == "False" and f["frame_build_ms"] == "" for f in inv if int(f["frame"]) == k)


@pytest.mark.slow
def test_a_caster_flagged_static_is_never_invalidated(run_dict):
    """``invalidate`` with the moving box flagged static (UE5's undefined case) re-casts nothing
    after frame 0 and gives ``static``'s ghosts and missing shadows, which stay after the box stops."""
    keys = [[0, 0, 0], [0.0, 1.2, 0.0], [0.0, 1.2, 0.0]]
    inv = _frames(run_dict(_config([{"frames": 3, "points": 200, "cache": "invalidate", "casters": [
        {"shape": "box", "keys": keys, "static": True}]}]), name="inv").out)
    static = _frames(run_dict(_config([{"frames": 3, "points": 200, "cache": "static", "casters": [
        {"shape": "box", "keys": keys}]}]), name="static").out)
    keep = ("frame", "scheme", "n_receivers", "n_ghost", "n_missing", "error_rate")
    assert [{k: f[k] for k in keep} for f in inv] == [{k: f[k] for k in keep} for f in static]
    assert all(int(f["n_ghost"]) > 0 for f in inv if f["frame"] == "2")
    assert all(float(f["recast_fraction"]) == 0.0 for f in inv if f["frame"] != "0")


def mi_points(pts):
    """numpy (n, 3) as a Mitsuba Point3f."""
    import mitsuba as mi
    return mi.Point3f(*(mi.Float(np.asarray(pts[:, c], np.float32)) for c in range(3)))
