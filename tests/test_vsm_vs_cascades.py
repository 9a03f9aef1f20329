"""Virtual maps against cascades (docs/vsm_vs_cascades.md): the equal-memory resolution against a
brute-force search, each receiver's distance to a cascade or level transition against the views' own
selection kernels (a point moved just short of it keeps its map, just past it changes map), and the
transition columns against numpy. Expected values: integer arithmetic, the float32 kernels
``face_of`` of the views (not the float64 code under test), numpy percentiles."""

import math

import numpy as np
import pytest

from test_virtual import DOWN, _camera, _points


def test_equal_memory_resolution_is_the_nearest_of_all_resolutions():
    """cascade_resolution(T, n): the R minimizing |n R^2 - T| over every R (brute force), the smaller on a tie."""
    from dsm.maps.budget import budget_gap, cascade_resolution
    rng = np.random.default_rng(1)
    R = np.arange(1, 20000, dtype=np.int64)
    for target in [*rng.integers(1, 80_000_000, 200), 491_520, 19_791_872, 3]:
        for n in (1, 4):
            want = int(R[np.argmin(np.abs(n * R * R - int(target)))])    # argmin: the first, the smaller R
            assert cascade_resolution(int(target), n) == want
    r = 350
    assert cascade_resolution(4 * r * r + 4 * r + 2, 4) == r            # 4 r^2 and 4 (r+1)^2 equally far
    assert cascade_resolution(491_520, 4) == 351                        # 492,804 against 490,000
    assert budget_gap(351, 4, 491_520) == pytest.approx(1284 / 491_520, rel=1e-12)
    with pytest.raises(ValueError, match="target > 0"):
        cascade_resolution(0, 4)


def _views():
    from dsm.core.types import VIRTUAL_PRESETS, CascadeSpec
    from dsm.maps.cascades import CascadeView
    from dsm.maps.virtual import VirtualView
    cam, pts = _camera(), _points(n=3000, dmin=0.2, dmax=300.0)
    box = (pts.min(0) - 1.0, pts.max(0) + 1.0)
    out = [("cascades", CascadeView(DOWN, CascadeSpec(count=4), cam, pts, box, 512), pts)]
    for name in ("ue5", "eevee"):
        out.append((name, VirtualView(DOWN, VIRTUAL_PRESETS[name], cam, pts[:50], box), pts))
    return cam, out


def _faces(view, pts):
    import mitsuba as mi
    p = mi.Point3f(*(mi.Float(pts[:, c].astype(np.float32)) for c in range(3)))
    return np.asarray(view.face_of(p).numpy(), int)


@pytest.mark.parametrize("which", ["cascades", "ue5", "eevee"])
def test_transition_distance_is_where_the_selection_changes(which):
    """A receiver moved 0.98 x its transition distance (toward or away from the camera: radially for a
    virtual map, along the view axis for cascades) keeps its map both ways; moved 1.02 x, one way
    changes it. The distance is in texels of its own map."""
    from dsm.truth.transition import transition_texels
    cam, views = _views()
    _, view, pts = next(v for v in views if v[0] == which)
    face = _faces(view, pts)
    gap = transition_texels(view, pts, face)
    texel = np.asarray(view.extents, float)[face] / view.resolution
    d = np.linalg.norm(pts - cam.origin, axis=1)
    axis = (pts - cam.origin) / d[:, None] if which != "cascades" else np.tile(cam.forward, (len(pts), 1))
    length = gap * texel
    ok = np.isfinite(gap) & (length > 1e-3 * d)         # far above float32's step at the point
    assert ok.sum() > 300 and len(np.unique(face[ok])) >= 3
    p, a, L = pts[ok], axis[ok], length[ok][:, None]
    short = [_faces(view, p + s * 0.98 * L * a) for s in (1, -1)]
    past = [_faces(view, p + s * 1.02 * L * a) for s in (1, -1)]
    f = face[ok]
    assert all(np.array_equal(x, f) for x in short)
    assert np.all((past[0] != f) | (past[1] != f))


def test_transition_columns_against_numpy():
    """tpp percentiles and share below 1 (numpy), receivers within 4 texels and the error rates on and off
    them; with no receiver near a transition its rate is undefined (NaN), never 0."""
    from dsm.truth.transition import TRANSITION_TEXELS, columns, transition_texels
    _, views = _views()
    _, view, pts = views[1]
    face = _faces(view, pts)
    rng = np.random.default_rng(5)
    tpp = rng.lognormal(0.0, 1.0, len(pts))
    wrong = rng.random(len(pts)) < 0.1
    got = columns(view, pts, face, tpp, wrong)
    near = transition_texels(view, pts, face) <= TRANSITION_TEXELS
    assert got["tpp_p10"] == pytest.approx(np.percentile(tpp, 10))
    assert got["tpp_p90"] == pytest.approx(np.percentile(tpp, 90))
    assert got["tpp_below_1"] == pytest.approx(np.count_nonzero(tpp < 1) / len(tpp))
    assert got["n_transition"] == near.sum() > 0
    assert got["transition_error_rate"] == pytest.approx(wrong[near].sum() / near.sum())
    assert got["off_transition_error_rate"] == pytest.approx(wrong[~near].sum() / (~near).sum())
    far = transition_texels(view, pts, face) > 50
    none = columns(view, pts[far], face[far], tpp[far], wrong[far])
    assert none["n_transition"] == 0 and math.isnan(none["transition_error_rate"])
    empty = columns(view, np.zeros((0, 3)), np.zeros(0, int), np.zeros(0), np.zeros(0, bool))
    assert all(math.isnan(empty[k]) for k in ("tpp_p10", "tpp_below_1", "transition_error_rate"))


def test_the_page_s_tables_are_the_committed_results():
    """docs/vsm_vs_cascades.md's measured part is what scripts/vsm_vs_cascades_page.py makes of the
    committed docs/vsm_vs_cascades/*.csv (a page edited by hand, or stale, fails), and its equal-memory
    rows keep the rule: the cascades' texels within 4 R + 2 of the virtual map's M."""
    import csv
    import importlib.util
    from conftest import ROOT
    from dsm.maps.budget import cascade_resolution
    spec = importlib.util.spec_from_file_location("vsm_page", ROOT / "scripts" / "vsm_vs_cascades_page.py")
    page = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(page)
    text = (ROOT / "docs" / "vsm_vs_cascades.md").read_text()
    assert page.BEGIN + "\n" + page.measured_text(ROOT / "docs" / "vsm_vs_cascades") + "\n" + page.END in text
    rows = list(csv.DictReader(open(ROOT / "docs" / "vsm_vs_cascades" / "comparison.csv")))
    virtual = {(r["scene_label"], r["preset"]): int(r["vsm_memory_texels"]) for r in rows if r["budget"] == "virtual"}
    mem = [r for r in rows if r["budget"] == "equal memory"]
    assert len(mem) == 4 * len(virtual)            # four schemes per scene and preset
    for r in mem:
        M, R = virtual[(r["scene_label"], r["preset"])], int(r["resolution"])
        assert R == cascade_resolution(M, 4) and abs(4 * R * R - M) <= 4 * R + 2     # half of 4(R+1)^2 - 4R^2
