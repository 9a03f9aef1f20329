"""Virtual shadow maps under [[motion]]: the page cache the policies act on (dsm.experiment.page_cache).

Known answers: with nothing moving every policy gives ``none``'s numbers bit for bit (a still path: every
column; a camera dolly that re-tags pages: every count and rate); ``invalidate`` under a sliding box gives
``none``'s counts frame by frame (its map is the frame's) and re-casts exactly the pages whose texel rays meet
the box's bounds at the page's frame or this one, counted here in numpy float64 from the page grid and the
bounds' outlines projected along the light; ``static`` keeps the stale pages (ghosts)."""
import csv
import math

import numpy as np
import pytest

from conftest import base_config

SUN = [-1.0, -0.3, -0.8]
TIMES = {"build_ms", "build_first_ms", "lookup_ms", "build_compile_ms", "build_peak_mb", "lookup_compile_ms",
         "lookup_kernels_compiled", "reference_ms", "moments_ms", "frame_build_ms", "fit_ms", "case"}
CASTS = {"maps_built", "map_built", "recast_fraction"}
PATHS = [{"label": "still", "frames": 3, "points": 200},
         {"label": "dolly", "frames": 4, "points": 200, "camera": "dolly", "offset": [0.0, 3.0, 0.0]},
         {"label": "slide", "frames": 3, "points": 200, "casters": [{"shape": "box", "offset": [0.0, 1.2, 0.0]}]}]


def _config(cache):
    return base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                       map={"virtual": {"preset": "ue5", "unit_cm": 100.0, "resolution": 256, "page_size": 32}},
                       light=[{"type": "directional", "direction": SUN}], scheme=[{"name": "constant", "bias": "1 texel"}],
                       motion=[{**p, "cache": cache} for p in PATHS])


def _rows(out, name):
    with open(out / name, newline="") as fh:
        return list(csv.DictReader(fh))


def _by_path(rows, drop=()):
    out = {}
    for r in rows:
        out.setdefault(r["motion"], []).append({k: v for k, v in r.items() if k not in TIMES | {"cache"} | set(drop)})
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    import dsm
    out = {}
    for cache in ("none", "static", "stagger:2", "invalidate", "static again"):
        # the report's section is read of the two static runs only (its GIF and plot, and that they repeat)
        res = dsm.run(_config(cache.split()[0]), out=tmp_path_factory.mktemp(cache.replace(":", "_").replace(" ", "_")) / "out",
                      report=cache.startswith("static"))
        out[cache] = (_rows(res.out, "frames.csv"), _rows(res.out, "metrics.csv"), res.out)
    return out


def test_nothing_moving_every_policy_gives_none_bit_for_bit(runs):
    """A still path: every column of frames.csv and metrics.csv equals ``none``'s under every policy (``stagger:2``
    but the maps it casts on time). A camera
    dolly re-tags pages (``none`` casts the map again, the page cache casts only the pages its pool lacks):
    every count and rate equals ``none``'s, and no frame has a ghost or a missing shadow."""
    for cache in ("static", "stagger:2", "invalidate"):
        drop = CASTS if cache == "stagger:2" else ()          # stagger casts on time, the others when needed
        frames, metrics = _by_path(runs[cache][0], drop), _by_path(runs[cache][1], drop)
        assert frames["still"] == _by_path(runs["none"][0], drop)["still"], cache
        assert metrics["still"] == _by_path(runs["none"][1], drop)["still"], cache
        assert _by_path(runs[cache][0], CASTS)["dolly"] == _by_path(runs["none"][0], CASTS)["dolly"], cache
        assert _by_path(runs[cache][1], CASTS)["dolly"] == _by_path(runs["none"][1], CASTS)["dolly"], cache
    dolly = [r for r in runs["static"][0] if r["motion"] == "dolly"]
    none = [r for r in runs["none"][0] if r["motion"] == "dolly"]
    # frame 1 re-tags pages (none casts again) that the pool already holds: the page cache casts none of them
    assert none[1]["map_built"] == "True" and float(dolly[1]["recast_fraction"]) == 0.0
    assert all(r["n_ghost"] == "0" and r["n_missing"] == "0" for r in dolly)


def test_invalidate_gives_the_frames_map_and_static_keeps_the_ghost(runs):
    """A box sliding under the sun: ``invalidate``'s counts and rates equal ``none``'s frame by frame, with no
    ghost or missing shadow, having re-cast part of the map (0 < recast_fraction < 1 at a frame); ``static``
    keeps the box's old shadow (ghosts at the last frame); ``stagger:2`` re-casts every page at frame 2."""
    pick = lambda cache: [r for r in runs[cache][0] if r["motion"] == "slide"]
    keep = lambda rows: [{k: v for k, v in r.items() if k not in TIMES | CASTS | {"cache"}} for r in rows]
    inv, none, static, stagger = pick("invalidate"), pick("none"), pick("static"), pick("stagger:2")
    assert keep(inv) == keep(none)
    assert all(r["n_ghost"] == "0" and r["n_missing"] == "0" for r in inv)
    assert any(0.0 < float(r["recast_fraction"]) < 1.0 for r in inv)
    assert int(static[-1]["n_ghost"]) > 0 and float(static[-1]["recast_fraction"]) < 1.0
    assert int(stagger[1]["n_ghost"]) > 0 and stagger[2]["recast_fraction"] == "1"
    own = ("n_receivers", "acne_rate", "peterpan_rate", "error_rate", "n_ghost", "n_missing")   # not the pair (1, 2)'s
    assert [stagger[2][k] for k in own] == [none[2][k] for k in own]


# ---------------------------------------------------------------- the pages a moved box invalidates

def _hull(p):
    """The convex hull of 2-D points ``p``, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(map(tuple, p))
    cross = lambda o, a, b: (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    def half(seq):
        out = []
        for q in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], q) <= 0:
                out.pop()
            out.append(q)
        return out[:-1]
    return np.array(half(pts) + half(pts[::-1]))


def _signed_distance_inside(hull, q):
    """Per point of ``q``, its least distance inside the hull's edges (negative: outside)."""
    a, b = hull, np.roll(hull, -1, axis=0)
    e = b - a
    n = np.stack([-e[:, 1], e[:, 0]], 1) / np.linalg.norm(e, axis=1, keepdims=True)    # inward (counter-clockwise)
    return ((q[:, None, :] - a[None]) * n[None]).sum(2).min(1)


def _expected_pages(view, boxes):
    """Per page of ``view``: whether a texel centre's ray (along the light) meets a box, from the centre's
    light-space place against the hull of the box's corners projected along the light; and the least
    distance of any centre to a hull's edge (world units)."""
    ex, ey = view.axes_np[0], view.axes_np[1]
    P = view.page_size
    hit, margin = np.zeros(len(view.pages), bool), math.inf
    for lo, hi in boxes:
        corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
        hull = _hull(np.stack([corners @ ex, corners @ ey], 1))
        for n, (f, px, py) in enumerate(view.pages):
            x0, y0, w = view.rects[f]
            s = w / view.resolution
            i, j = np.meshgrid(np.arange(px * P, px * P + P) + 0.5, np.arange(py * P, py * P + P) + 0.5)
            q = np.stack([x0 + i.ravel() * s, y0 + j.ravel() * s], 1)
            d = _signed_distance_inside(hull, q)
            hit[n] |= bool((d > 0).any())
            margin = min(margin, float(np.abs(d).min()))
    return hit, margin


def test_invalidate_recasts_exactly_the_pages_the_swept_bounds_touch():
    """A UE5 clipmap over receivers on a ground plane, every page cached at frame 0 with a box at one place:
    at frame 1 (the box moved) ``invalidate`` casts the pages a texel ray of which meets the box's bounds at
    frame 0 or 1 (counted in numpy, no texel centre within 3e-5 of an outline) and every page the pool lacks;
    ``static`` casts only those it lacks; ``none`` every page; ``stagger:2`` at frame 2 every page."""
    from dsm.core.types import VIRTUAL_PRESETS
    from dsm.experiment import cache
    from dsm.experiment.page_cache import PagePool, Slot, plan
    from dsm.maps.virtual import VirtualView
    from dsm.scenes.camera import Camera
    from dataclasses import replace
    tx = math.tan(math.radians(40.0) / 2)
    cam = Camera(np.array([0.0, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                 np.array([-1.0, 0.0, 0.0]), tx, tx, 1e-2, 1e4, 64, 64)
    g = np.stack(np.meshgrid(np.linspace(-6, 6, 61), np.linspace(0.5, 20, 79)), -1).reshape(-1, 2)
    pts = np.concatenate([g, np.zeros((len(g), 1))], 1)
    spec = replace(VIRTUAL_PRESETS["ue5"], unit_cm=100.0, resolution=512, page_size=32)
    view = VirtualView((-1.0, -0.3, -0.8), spec, cam, pts, (np.array([-8.0, -2.0, 0.0]), np.array([8.0, 22.0, 2.0])))
    boxes = [(np.array([-0.7, 3.1, 0.0]), np.array([0.6, 4.3, 1.1])), (np.array([-0.1, 4.0, 0.0]), np.array([1.2, 5.2, 1.1]))]
    want, margin = _expected_pages(view, boxes)
    # the kit grows the bounds by 8 float32 steps at the coordinates (about 1.3e-5 here): no centre that near
    assert margin > 3e-5 and 0 < want.sum() < len(want) - 5
    keys = view.page_keys()
    full = lambda: PagePool(slots={k: Slot(i, 0, ("at 0",)) for i, k in enumerate(keys)})
    bounds = lambda f: [boxes[f]]
    got = plan(full(), view, 1, ("at 1",), cache.rule("invalidate"), True, bounds)
    assert np.array_equal(got, want)
    lacking = full()
    for k in keys[:3]:
        del lacking.slots[k]
    got = plan(lacking, view, 1, ("at 1",), cache.rule("invalidate"), True, bounds)
    assert np.array_equal(got, want | (np.arange(len(keys)) < 3))
    assert np.array_equal(plan(lacking, view, 1, ("at 1",), cache.rule("static"), False, bounds), np.arange(len(keys)) < 3)
    assert plan(full(), view, 1, ("at 1",), cache.rule("none"), False, bounds).all()
    assert not plan(full(), view, 1, ("at 0",), cache.rule("none"), False, bounds).any()
    assert not plan(full(), view, 1, ("at 1",), cache.rule("stagger:2"), False, bounds).any()
    assert plan(full(), view, 2, ("at 1",), cache.rule("stagger:2"), False, bounds).all()


# ---------------------------------------------------------------- the report's section

def test_cache_gif_shows_each_frames_ghosts_and_is_the_same_between_identical_runs(runs):
    """Each frame of a sliding box's cache GIF under ``static`` holds as many pixels in the ghost's colour and in
    the missing shadow's as frames.csv counts ghosts and missing shadows (one receiver a camera pixel); two
    identical runs write the same GIF and budget plot, byte for byte; cache.md lists every motion case."""
    from PIL import Image
    from dsm.report.sections import cache as section
    out, again = runs["static"][2], runs["static again"][2]
    rows = [r for r in runs["static"][0] if r["motion"] == "slide"]
    folder = out / "images" / "plane_box_0_directional"
    gif = folder / f"{rows[0]['case']}_cache.gif"
    im = Image.open(gif)
    assert im.n_frames == len(rows) and sum(int(r["n_ghost"]) for r in rows) > 0
    for t, r in enumerate(rows):
        im.seek(t)
        rgb = np.asarray(im.convert("RGB"))
        count = lambda colour: int((rgb == colour).all(2).sum())
        assert (count(section.GHOST_COLOR), count(section.MISSING_COLOR)) == (int(r["n_ghost"]), int(r["n_missing"])), t
    assert gif.read_bytes() == (again / gif.relative_to(out)).read_bytes()
    plot = next((out / "plots").glob("cache_budget_plane_box_0_directional_vsm_ue5*.png"))
    assert plot.read_bytes() == (again / plot.relative_to(out)).read_bytes()
    table = (out / "cache.md").read_text()
    assert all(f"| {r['case']} |" in table for r in runs["static"][1])


def test_a_spots_virtual_map_keeps_its_pages_the_same_way(run_dict):
    """A spot's virtual map (EEVEE's punctual rule) under a sliding box: ``invalidate``'s counts and rates equal
    ``none``'s frame by frame with no ghost, re-casting part of the pages; ``static`` leaves ghosts."""
    cfg = lambda cache: base_config(
        scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
        light=[{"type": "spot", "position": [0.0, 2.5, 0.8], "target": [0.0, -0.5, 0.0], "cutoff": 40.0}],
        map={"virtual": {"preset": "eevee_punctual", "resolution": 2048, "page_size": 64, "lod_bias": -2.0}},
        scheme=[{"name": "constant", "bias": "1 texel"}],
        motion=[{"frames": 3, "points": 200, "cache": cache, "casters": [{"shape": "box", "offset": [0.6, 0.0, 0.0]}]}])
    runs = {c: _rows(run_dict(cfg(c), c).out, "frames.csv") for c in ("none", "static", "invalidate")}
    keep = lambda rows: [{k: v for k, v in r.items() if k not in TIMES | CASTS | {"cache"}} for r in rows]
    assert keep(runs["invalidate"]) == keep(runs["none"])
    assert all(r["n_ghost"] == "0" and r["n_missing"] == "0" for r in runs["invalidate"])
    assert any(0.0 < float(r["recast_fraction"]) < 1.0 for r in runs["invalidate"])
    assert int(runs["static"][-1]["n_ghost"]) + int(runs["static"][-1]["n_missing"]) > 0
