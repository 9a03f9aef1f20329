"""report.html laid out for a 1280 px screen (issue 75): no box wider than the page, plots side by side
in a grid, every figure's title inside its image and clear of its panels' titles, the error classes'
legend beside the case images. Headless Chromium as conftest.chrome drives it."""
import pytest

from conftest import base_config
from conftest import all_images_loaded, chrome

LONG = ("floating_plate, light 0:directional, orthographic, R = 128: rates against each scheme's swept "
        "parameter (one column per unit), a title long enough to wrap to three lines in a narrow figure")


@pytest.mark.parametrize("title", ["short title", LONG])
def test_a_figures_title_lies_inside_it_and_above_its_panels_titles(tmp_path, title):
    """Measured on the drawn figure (matplotlib's own extents, in pixels): the title's box inside the
    figure's, its bottom above every panel's title and axes (a wrapped title overlapped them)."""
    from dsm.report import figures
    series = {"constant": [(0.5, 0.1, 0.2), (1.0, 0.01, 0.3)], "normal_offset": [(0.5, 0.2, 0.1), (2.0, 0.0, 0.4)]}
    # one column: the narrowest figure, where a long title wraps to three lines
    fig = figures.draw_lines(tmp_path / "f.png", title, [("lengths in texel", "parameter value [texel]", series, {})])
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    top = fig._suptitle.get_window_extent(r)
    assert top.x0 >= 0 and top.x1 <= fig.bbox.width and top.y1 <= fig.bbox.height
    for ax in fig.axes:
        below = max(ax.get_window_extent(r).y1, ax.title.get_window_extent(r).y1)
        assert top.y0 > below, (top, below)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    import dsm
    cfg = base_config(experiment={"name": "layout"}, camera={"resolution": [32, 32]},
                      scene=[{"builtin": "plane"}, {"builtin": "plane_box"}, {"builtin": "l_shape"}],
                      light=[{"type": "scene"}, {"type": "spot", "position": [-2.0, 2.5, 2.6], "target": [0, 0, 0],
                                                  "cutoff": 40}],
                      map={"resolution": [16, 32], "filter": ["nearest", "pcf_bilinear"]},
                      scheme=[{"name": "none"}, {"name": "constant", "bias": ["1 texel", 0.05, "2^-24 range"]},
                              {"name": "slope_scaled"}, {"name": "normal_offset"}, {"name": "adaptive"}])
    res = dsm.run(cfg, out=tmp_path_factory.mktemp("layout") / "run")
    drv = chrome()
    drv.set_window_size(1280, 900)
    drv.get((res.out / "report.html").as_uri())
    assert all_images_loaded(drv) == []
    yield res, drv
    drv.quit()


WIDER_JS = """
const page = document.documentElement.clientWidth, out = [];
// every element shown: none reaches past the page, unless a box that scrolls sideways holds it
for (const e of document.querySelectorAll('body *')) {
  if (e.closest('#zoom') || e.offsetParent === null) continue;
  const r = e.getBoundingClientRect();
  let box = e.parentElement, held = false;
  for (; box && box !== document.body; box = box.parentElement) {
    const s = getComputedStyle(box).overflowX;
    if ((s === 'auto' || s === 'scroll') && box.getBoundingClientRect().right <= page + 0.5) { held = true; break; }
  }
  if (!held && r.right > page + 0.5) out.push(e.tagName + '#' + (e.id || e.className) + ' ' + Math.round(r.right));
}
return [page, document.documentElement.scrollWidth, out];
"""


@pytest.mark.slow
def test_no_element_is_wider_than_the_page_at_1280_px(report):
    _, drv = report
    page, scroll, wider = drv.execute_script(WIDER_JS)
    assert wider == [] and scroll <= page


@pytest.mark.slow
def test_the_plots_sit_in_a_grid_and_each_shows_whole(report):
    """More than one figure a row where they fit, and each image whole in its box (its title with it)."""
    _, drv = report
    boxes = drv.execute_script(
        "return Array.from(document.querySelectorAll('.plots .grid')).map(g => Array.from(g.children)"
        ".map(f => { const i = f.querySelector('img'), b = f.querySelector('.figbox').getBoundingClientRect();"
        " const r = i.getBoundingClientRect(); return [Math.round(r.top), r.left >= b.left - 0.5 && r.right <= b.right + 0.5,"
        " i.naturalWidth]; }))")
    assert boxes and all(len(g) for g in boxes)
    assert all(whole for g in boxes for _, whole, _ in g)
    page = drv.execute_script("return document.documentElement.clientWidth")
    for g in boxes:                 # figures narrower than half the page: at least two on one row
        small = [top for top, _, w in g if 2 * w + 40 < page]
        if len(small) > 1:
            assert len(set(small)) < len(small), g


@pytest.mark.slow
def test_the_class_legend_sits_beside_the_case_images(report):
    """A click on a case shows its images; the colours' legend stays, right of them and level with them."""
    _, drv = report
    drv.execute_script("document.querySelector('#case-table tbody tr').click()")
    imgs, legend = drv.execute_script(
        "const box = e => { const r = e.getBoundingClientRect(); return [r.left, r.right, r.top, r.bottom]; };"
        "return [Array.from(document.querySelectorAll('#viewer img')).map(box),"
        " box(document.querySelector('#class-legend'))]")
    assert imgs
    assert legend[0] >= max(i[1] for i in imgs)                          # right of every image
    assert legend[2] < max(i[3] for i in imgs) and legend[3] > min(i[2] for i in imgs)    # level with them
    assert "acne" in drv.find_element("css selector", "#class-legend").text
