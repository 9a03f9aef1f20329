"""The report's drawing shortcuts (dsm/report/canvas.py) against matplotlib's own drawing: a text
drawn from its cached whole-string bitmap lands where matplotlib's glyph-by-glyph drawing puts
it, with the same ink; a figure drawn on a reused Figure equals the same figure drawn new, pixel
for pixel; the case points (markers, not scatter collections) hold every case's values."""
import math

import numpy as np
import pytest


def _pixels(fig, cached: bool) -> np.ndarray:
    """The figure drawn at 72 dpi, as an (H, W) grey array: by the kit's canvas or matplotlib's."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from dsm.report import canvas
    cv = canvas.canvas(fig) if cached else FigureCanvasAgg(fig)
    fig.dpi = 72
    cv.draw()
    return np.asarray(cv.buffer_rgba())[..., :3].astype(np.float64).mean(-1)


def _ink_box(grey: np.ndarray):
    ys, xs = np.nonzero(grey < 200)
    return ys.min(), ys.max(), xs.min(), xs.max()


@pytest.mark.parametrize("rotation", [0, 90])
def test_a_cached_text_lands_where_matplotlib_draws_it_with_the_same_ink(rotation):
    from matplotlib.figure import Figure
    make = lambda color="k": Figure(figsize=(3, 3)).text(0.2, 0.3, "peter-panning rate 0.001", fontsize=7,
                                                         rotation=rotation, color=color).figure
    want, got = _pixels(make(), False), _pixels(make(), True)
    # whole-pixel placement of the string's bitmap: within a pixel of the glyph-by-glyph placement
    assert np.abs(np.subtract(_ink_box(got), _ink_box(want))).max() <= 1
    ink = lambda g: (255 - g).sum()
    assert ink(got) == pytest.approx(ink(want), rel=0.05)
    # drawn again from the cache: the same pixels; the colour is the text's, not the cached one's
    assert np.array_equal(_pixels(make(), True), got)
    fig = make("red")
    from dsm.report import canvas
    cv = canvas.canvas(fig)
    fig.dpi = 72
    cv.draw()
    rgb = np.asarray(cv.buffer_rgba())[..., :3].astype(int)
    assert ((rgb[..., 0] > 200) & (rgb[..., 1] < 80)).sum() > 20


def _png(path) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(path))


def _lines_columns(empty_row: bool, xs):
    """One column of draw_lines: two series over ``xs``; the lower row's rates undefined when ``empty_row``."""
    series = {f"s{k}": [(x, 0.01 * (k + 1) / (i + 1), math.nan if empty_row else 0.001 * (i + k))
                        for i, x in enumerate(xs)] for k in range(2)}
    return [("schemes", "x", series, {})]


def test_a_figure_drawn_on_a_reused_figure_equals_it_drawn_new(tmp_path):
    """Each figure kind drawn new, then after another figure of its layout (other scales, limits,
    panels with and without data) on the same Figure: the same pixels."""
    from dsm.report import canvas, figures
    curve = (np.array([0.0, 0.01, 1.0]), np.array([1.0, 0.05, 0.0]))
    pairs = {
        "lines": ((figures.draw_lines, ("A", _lines_columns(False, [32, 64, 128]), ("a", "b"), True)),
                  (figures.draw_lines, ("B", _lines_columns(True, [0.5, 1.0, 2.0]), ("a", "b"), False))),
        "pareto": ((figures.draw_pareto, ("A", [{"x": (0, [(0.1, 0.5), (300.0, 1e-4)])}], [(0.1, 0.5)])),
                   (figures.draw_pareto, ("B", [{"y": (3, [(1.0, 0.0), (2.0, 0.02)])}], [(1.0, 0.0)]))),
        "tradeoff": ((figures.draw_tradeoff, ("A", [("R = 1", [("f", 0, curve, curve, [(0.5, 0.5)])])])),
                     (figures.draw_tradeoff, ("B", [("R = 2", [("g", 1, curve, (curve[1], curve[0]), [])])]))),
    }
    for kind, ((fa, aa), (fb, ab)) in pairs.items():
        new = fb(tmp_path / f"{kind}_new.png", *ab)
        with canvas.reusing():
            first = fa(tmp_path / f"{kind}_a.png", *aa)
            again = fb(tmp_path / f"{kind}_again.png", *ab)
        assert again is first and again is not new, kind            # reused inside, new outside
        assert np.array_equal(_png(tmp_path / f"{kind}_again.png"), _png(tmp_path / f"{kind}_new.png")), kind
        assert not np.array_equal(_png(tmp_path / f"{kind}_a.png"), _png(tmp_path / f"{kind}_new.png")), kind


def test_the_points_of_the_pareto_and_trade_off_figures_are_every_case(tmp_path):
    from dsm.report import figures
    rng = np.random.default_rng(5)
    pts = {s: (k, [(float(t), float(e)) for t, e in zip(10 ** rng.uniform(-1, 1, 4), rng.uniform(0, 1, 4))])
           for k, s in enumerate(("a", "b"))}
    front = [(0.2, 0.3), (1.0, 0.1)]
    fig = figures.draw_pareto(tmp_path / "p.png", "t", [pts], front)
    drawn = [ln for ln in fig.axes[0].get_lines() if ln.get_marker() == "o"]
    want = [np.array(v[1]) for v in pts.values()] + [np.array(front)]
    assert len(drawn) == len(want)
    for ln, w in zip(drawn, want):
        assert np.array_equal(np.column_stack([ln.get_xdata(), ln.get_ydata()]), w)
    assert fig.axes[0].legend_texts == ["a", "b", "on the frontier (error, bytes, rays)"]
    curve = (np.array([0.0, 1.0]), np.array([1.0, 0.0]))
    cases = [(0.01, 0.2), (0.5, 0.003)]
    fig = figures.draw_tradeoff(tmp_path / "t.png", "t", [("R = 1", [("f", 0, curve, curve, cases)])])
    from matplotlib.collections import CircleCollection
    (dots,) = [c for c in fig.axes[0].collections if isinstance(c, CircleCollection)]
    assert np.array_equal(dots.get_offsets(), np.array(cases))
