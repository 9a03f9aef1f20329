"""metrics.csv's acne split (``n_acne_self``, ``n_acne_edge``) decided by surface, not by shape
(docs/design.md, *Metrics*; dsm.maps.lookup.on_own_surface): geometry merged into one file
gives the split of the same geometry as separate shapes; a plane alone shadows only itself;
under a floating plate's outline the ground's acne is the plate's, ``edge``."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import base_config
from dsm.schemes import REGISTRY

EVERY_SCHEME = [{"name": m.NAME} for m in REGISTRY]
# a "_closed" culling culls by a shape's closedness: merging an open ground into a closed box's file
# changes the map itself, not only its split; second depth's face-wise culling keeps the map the same
SAME_MAP = [{"name": "second_depth", "culling": "front"} if s["name"] == "second_depth" else s for s in EVERY_SCHEME]
LIGHT = [-0.4, -0.3, -1.0]


def _box(lo, hi):
    """(vertices, faces) of an axis-aligned box, faces wound outward (1-based in OBJ)."""
    v = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)], float)
    f = [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
         [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
    return v, np.array(f)


def _obj(parts) -> str:
    """One OBJ of the (vertices, faces) ``parts``."""
    lines, base = [], 0
    for v, f in parts:
        lines += [f"v {a:.17g} {b:.17g} {c:.17g}" for a, b, c in v]
        lines += [f"f {a + 1 + base} {b + 1 + base} {c + 1 + base}" for a, b, c in f]
        base += len(v)
    return "\n".join(lines) + "\n"


def _xml(files) -> str:
    """A Mitsuba scene of the OBJ ``files``, seen by one camera looking down at the box's corner."""
    shapes = "".join(f'<shape type="obj" id="s{k}"><string name="filename" value="{name}"/></shape>'
                     for k, name in enumerate(files))
    return f"""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="5, -7, 6" target="0, 0, 0.3" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="96"/><integer name="height" value="96"/></film>
    </sensor>{shapes}
</scene>
"""


@pytest.mark.slow
def test_merged_geometry_gives_the_split_of_separate_shapes(run_dict, tmp_path):
    """The ground and a box as two shapes and the same triangles merged into one OBJ: the same
    self and edge counts for every scheme (by shape, the merged file's acne was all self); second
    depth culls front faces, not those of closed shapes (a closedness the merging changes)."""
    ground = (np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    box = _box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])
    (tmp_path / "ground.obj").write_text(_obj([ground]))
    (tmp_path / "box.obj").write_text(_obj([box]))
    (tmp_path / "merged.obj").write_text(_obj([ground, box]))
    (tmp_path / "two.xml").write_text(_xml(["ground.obj", "box.obj"]))
    (tmp_path / "one.xml").write_text(_xml(["merged.obj"]))
    cfg = base_config(scene=[{"file": str(tmp_path / "two.xml")}, {"file": str(tmp_path / "one.xml")}],
                      camera={"resolution": [96, 96]}, map={"resolution": 96}, scheme=SAME_MAP,
                      light=[{"type": "directional", "direction": LIGHT}])
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    by = {}
    for r in res.rows:
        by.setdefault(r["scheme"], {})[r["scene"]] = r
    assert len(by) == len(EVERY_SCHEME)
    edge = 0
    for scheme, pair in by.items():
        two, one = (pair[k] for k in sorted(pair, key=lambda s: "one" in s))
        # (peter-panning is not compared: a continuation ray leaves a hit by its shape's error bound,
        # which the merged file's larger extent widens, so z2 may differ by rounding)
        for col in ("n_receivers", "n_gt_lit", "n_acne", "n_acne_self", "n_acne_edge"):
            assert two[col] == one[col], (scheme, col, two[col], one[col])
        assert two["n_acne_self"] + two["n_acne_edge"] == two["n_acne"]
        edge += one["n_acne_edge"]
    assert edge > 0        # the box's outline puts acne on the ground in the merged file too


@pytest.mark.slow
def test_a_tilted_plane_alone_shadows_only_itself(run_dict):
    """One plane, tilted off every axis, under a directional light and a spot light whose cone lies
    inside the plane (no texel of a receiver looks past the plane's edge): every acne receiver's
    texel holds the plane itself, so all acne is ``self``."""
    cfg = base_config(scene=[{"builtin": "plane", "tilt": 60.0, "azimuth": 30.0}], camera={"resolution": [96, 96]},
                      map={"resolution": 64}, scheme=EVERY_SCHEME,
                      light=[{"type": "directional", "direction": [0.1, 0.2, -1.0]},
                             {"type": "spot", "position": [0.0, 0.0, 4.0], "direction": [0.0, 0.0, -1.0],
                              "cutoff": 10.0}])
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    for r in res.rows:
        assert r["n_acne_edge"] == 0 and r["n_acne_self"] == r["n_acne"], (r["light"], r["scheme"], r["n_acne"])
    for r in res.where(scheme="none").rows:         # no bias on a tilted plane: acne in numbers
        assert r["n_acne"] > 0.2 * r["n_gt_lit"] > 100, (r["light"], r["n_acne"], r["n_gt_lit"])


def _texel_centre_rays(view, p):
    """(origins, direction) in float64 of the light rays through the centres of the texels that
    hold world points ``p`` in an orthographic ``view`` (its frame and square), and each point's
    distance to its texel's border in texels (near 0: float32 may pick the neighbour)."""
    o, (ex, ey, ez) = view.origin_np, view.axes_np
    s = view.extent / view.resolution
    u, v = (p - o) @ ex / s, (p - o) @ ey / s
    iu, iv = np.floor(u), np.floor(v)
    border = np.minimum.reduce([u - iu, iu + 1 - u, v - iv, iv + 1 - v])
    return o + np.outer((iu + 0.5) * s, ex) + np.outer((iv + 0.5) * s, ey), ez, border


def _hits_quad(o, d, quad):
    """Whether rays (o, d) meet the convex planar polygon ``quad`` (4, 3) at t > 0, and how far
    inside its outline (negative: outside), in world units."""
    n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    n /= np.linalg.norm(n)
    t = ((quad[0] - o) @ n) / (d @ n)
    x = o + np.outer(t, d)
    inside = np.full(len(o), np.inf)
    for a, b in zip(quad, np.roll(quad, -1, axis=0)):
        e = np.cross(n, b - a)
        inside = np.minimum(inside, (x - a) @ (e / np.linalg.norm(e)))
    return (t > 0) & (inside >= 0), inside


def test_ground_acne_under_a_floating_plate_is_edge():
    """No bias, the plate 0.3 over the ground: a ground receiver whose texel's centre ray meets the
    plate (the plate's outline, derived here in float64) is acne of another surface, ``edge``;
    every other acne receiver (the ground's and the plate's own rounding) is ``self``."""
    import dsm.pipeline as pl
    from dsm.truth.metrics import compute
    sd = pl.load_scene(pl.scene_spec({"builtin": "floating_plate", "gap": 0.3}), (128, 128))
    gb = pl.gbuffer(sd)
    light = pl.LightSpec("directional", direction=(0.45, 0.2, -1.0))
    setup = pl.light_setup(sd, gb, light, "sun")
    p = pl.points_np(setup.p).astype(np.float64)
    view = pl.make_view(setup.light, 96, p, sd.bbox)
    smap = pl.store(pl.build_map(sd.scene, view), "float32")
    rx = pl.receivers(smap.view, setup, sd.diagonal)
    spec = pl.scheme_spec({"name": "none"})
    v, _ = pl.visibility(spec, rx, smap)
    acne = setup.v_star & (v.numpy() < 0.5)
    own = pl.own_surface(spec, rx, smap, smap).numpy().astype(bool)

    names = [s.id() for s in sd.scene.shapes()]
    plate = np.asarray(sd.scene.shapes()[names.index("plate")].vertex_positions_buffer(), np.float64).reshape(-1, 3)
    plate = plate[np.argsort(np.arctan2(*(plate - plate.mean(0))[:, :2].T[::-1]))]   # around its outline
    on_ground = np.asarray(setup.shape) == names.index("ground")
    o, d, border = _texel_centre_rays(view, p)
    under, inside = _hits_quad(o, np.asarray(d, float), plate)
    clear = (border > 1e-3) & (np.abs(inside) > 1e-3 * view.extent / view.resolution)
    expected_edge = acne & on_ground & under
    assert expected_edge[clear].sum() > 5 and (acne & ~expected_edge)[clear].sum() > 5
    assert np.array_equal((acne & ~own)[clear], expected_edge[clear])
    m = compute(v.numpy(), setup.v_star, own, setup.occluder_dist)
    assert m["n_acne_edge"] == int((acne & ~own).sum()) and m["n_acne_self"] == int((acne & own).sum())


@pytest.mark.slow
def test_the_split_does_not_depend_on_the_scene_scale(run_dict):
    """The box on the ground at scale 1 and 1024 (a power of two: every float scales exactly): the
    same self and edge counts for every scheme, both present (the rule's lengths are texels)."""
    cfg = base_config(scene=[{"builtin": "plane_box", "scale": [1.0, 1024.0]}], camera={"resolution": [64, 64]},
                      map={"resolution": 64}, scheme=EVERY_SCHEME)
    res = run_dict(cfg)
    assert res.run["n_failed"] == 0
    by = {}
    for r in res.rows:
        by.setdefault(r["scheme"], []).append((r["n_acne"], r["n_acne_self"], r["n_acne_edge"]))
    assert len(by) == len(EVERY_SCHEME)
    for scheme, (small, large) in by.items():
        assert small == large, (scheme, small, large)
    assert by["none"][0][1] > 100 and sum(v[0][2] for v in by.values()) > 0
