"""The report's section on moving casters (dsm.report.sections.cache): the cache GIF's frames and colours, and the
budget plot's points, against values written out here."""
import math

import numpy as np


def test_cache_gif_frames_are_the_classes_with_ghosts_and_missing_in_their_colours(tmp_path):
    """A GIF of two frames: every pixel's colour is its class's grey (the class colour's luminance at DIM) except
    the ghosts' and missing shadows', in GHOST_COLOR and MISSING_COLOR; writing it again gives the same bytes."""
    from PIL import Image
    from dsm.report.sections import cache as section
    from dsm.truth import metrics
    rng = np.random.default_rng(4)
    classes = [rng.integers(0, len(metrics.CLASS_COLORS), (9, 7)).astype(np.uint8) for _ in range(2)]
    marks = [rng.integers(0, 3, (9, 7)).astype(np.uint8) for _ in range(2)]
    section.write_gif(tmp_path / "a.gif", classes, marks)
    section.write_gif(tmp_path / "b.gif", classes, marks)
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()
    im = Image.open(tmp_path / "a.gif")
    assert im.n_frames == 2
    for t in range(2):
        im.seek(t)
        rgb = np.asarray(im.convert("RGB"), np.int64)
        grey = np.round(0.45 * (metrics.CLASS_COLORS.astype(float) @ [0.299, 0.587, 0.114]))[classes[t]]
        want = np.repeat(grey[..., None], 3, 2)
        want[marks[t] == 1] = (0, 220, 120)
        want[marks[t] == 2] = (255, 140, 0)
        assert np.array_equal(rgb, want), t


def test_budget_points_sum_the_rates_and_leave_out_the_undefined():
    """A case's point is (its recast_fraction, ghost_rate + missing_rate), grouped by scene, light and layout; a case with an undefined rate and a
    still case (no cache) have none."""
    from dsm.report.sections.cache import budget_points
    rows = [{"motion": "p", "cache": "static", "scene": "s", "light": "0:directional", "case": "0001",
             "ghost_rate": 0.25, "missing_rate": 0.5, "recast_fraction": 0.2},
            {"motion": "p", "cache": "none", "scene": "s", "light": "0:directional", "case": "0002",
             "ghost_rate": 0.0, "missing_rate": math.nan, "recast_fraction": 1.0},
            {"motion": "", "cache": "", "scene": "s", "light": "0:directional", "case": "0003",
             "ghost_rate": math.nan, "missing_rate": math.nan, "recast_fraction": math.nan}]
    assert budget_points(rows) == {("s", "0:directional", ""): [("static", 0.2, 0.75, "p")]}
