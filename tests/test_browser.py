"""report.html in a real browser: headless Chromium driven by Selenium (Debian's chromium and
chromium-driver, which scripts/setup installs when it runs as root). Opened from the file system,
it shows the summary and the case table in the live DOM, and a click on the acne-rate header
orders the rows as metrics.csv's values say."""
import csv
import math

import pytest

from conftest import all_images_loaded, base_config, chrome
from helpers_grad import tiny_grad_run  # noqa: F401  (a session fixture, shared with test_grad_report)


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    import dsm
    cfg = base_config(experiment={"name": "browser"}, camera={"resolution": [32, 32]},
                      scene=[{"builtin": "plane"}, {"builtin": "plane_box"}], map={"resolution": [16, 32]},
                      scheme=[{"name": "none"}, {"name": "constant", "bias": ["1 texel", 0.05]}, {"name": "adaptive"}])
    res = dsm.run(cfg, out=tmp_path_factory.mktemp("browser") / "run")
    drv = chrome()
    drv.get((res.out / "report.html").as_uri())
    yield res, drv
    drv.quit()


@pytest.fixture(scope="module")
def chromium():
    """Headless Chromium (conftest.chrome), one start (a second or more of CPU each) for the tests that load
    their own page: the leaderboard's, a contender's and the grad report's; ``page`` keeps its own (its tests
    read the state the one before left)."""
    drv = chrome()
    yield drv
    drv.quit()


@pytest.fixture
def browser(chromium):
    """The shared Chromium at 1280 x 900, the size a fresh one starts at."""
    chromium.set_window_size(1280, 900)
    return chromium


def _csv(res):
    with open(res.out / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _visible_cases(drv):
    return drv.execute_script("return Array.from(document.querySelectorAll('#case-table tbody tr'))"
                              ".filter(r => !r.hidden).map(r => r.dataset.case)")


@pytest.mark.slow
def test_the_page_shows_the_summary_and_the_cases(page, tmp_path):
    res, drv = page
    shot = tmp_path / "report.png"
    assert drv.save_screenshot(str(shot))
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    rows = _csv(res)
    instances = {(r["scheme"], r["preset"] or r["params"]) for r in rows}
    summary = drv.execute_script("return Array.from(document.querySelectorAll('#summary-table tbody tr'))"
                                 ".map(r => [r.cells[0].textContent, r.cells[1].textContent])")
    assert {tuple(x) for x in summary} == instances and len(summary) == len(instances) == 4
    # the best scheme per scene and light is on the first screen
    best = drv.find_element("id", "best")
    assert best.is_displayed() and best.location["y"] < 900
    assert drv.execute_script("return document.querySelectorAll('#best tbody tr').length") == 2
    assert _visible_cases(drv) == [r["case"] for r in rows]
    # no request leaves the file system
    assert drv.execute_script("return Array.from(document.querySelectorAll('[src],[href]'))"
                              ".every(e => !/^https?:/.test(e.getAttribute('src') || e.getAttribute('href')))")


@pytest.mark.slow
def test_clicking_the_acne_rate_header_orders_the_rows(page):
    res, drv = page
    rows = _csv(res)
    drv.execute_script("window.scrollTo(0, 0)")
    header = next(th for th in drv.find_elements("css selector", "#case-table thead th") if th.text == "acne rate")
    value = lambda r: float(r["acne_rate"]) if r["acne_rate"] != "" else math.nan
    ascending = sorted(rows, key=lambda r: (math.isnan(value(r)), value(r) if not math.isnan(value(r)) else 0))
    header.click()
    assert header.get_attribute("aria-sort") == "ascending"
    assert _visible_cases(drv) == [r["case"] for r in ascending]
    assert [value(r) for r in ascending] != [value(r) for r in rows]      # the click changed the order
    header.click()
    descending = sorted(ascending, key=lambda r: (math.isnan(value(r)), -value(r) if not math.isnan(value(r)) else 0))
    assert header.get_attribute("aria-sort") == "descending"
    assert _visible_cases(drv) == [r["case"] for r in descending]


def test_filtering_and_a_case_s_images(page):
    from selenium.webdriver.support.ui import Select
    res, drv = page
    rows = _csv(res)
    Select(drv.find_element("css selector", ".filters select[name=scene]")).select_by_value("plane_box")
    shown = _visible_cases(drv)
    assert sorted(shown) == sorted(r["case"] for r in rows if r["scene"] == "plane_box")
    assert drv.find_element("id", "shown").text == str(len(shown))
    Select(drv.find_element("css selector", ".filters select[name=scene]")).select_by_value("")
    case = rows[-1]["case"]
    drv.find_element("css selector", f"#case-table tbody tr[data-case='{case}']").click()
    imgs = drv.find_elements("css selector", "#viewer img")
    assert [i.get_attribute("alt") for i in imgs] == [f"shading (tinted) of case {case}",
                                                      f"error classes (tinted) of case {case}",
                                                      f"exact image of case {case}", f"shadow image of case {case}",
                                                      f"error image of case {case}"]
    assert [c.text for c in drv.find_elements("css selector", "#viewer figcaption")] == [
        "error classes over the display render (N.L)", "exact shading (display render, V*)",
        "shading under the shadow map (Lambert, ambient in shadow)", "error classes (colours beside)"]
    # the images load from the file system (a broken link has no natural width)
    loaded = drv.execute_async_script("const done = arguments[0];"
                                      "const im = Array.from(document.querySelectorAll('#viewer img'));"
                                      "Promise.all(im.map(i => i.decode().catch(() => null)))"
                                      ".then(() => done(im.map(i => i.complete ? i.naturalWidth : 0)))")
    # the camera's 32 px images, and the display renders at ten times that (at least 320 px a side)
    assert loaded == [320, 32, 320, 32, 32]


def _record(scene, contender, rate, n=1000, **more):
    """A hand-made benchmark record: acne alone at ``rate`` of ``n`` receivers (``more`` adds or overrides keys)."""
    return {"scene": scene, "unit": "m", "light": "directional", "contender": contender, "n_receivers": n,
            "n_acne": int(rate * n) if n else 0, "n_peterpan": 0, "acne_rate": rate, "peterpan_rate": 0.0,
            "error_rate": rate, "texel_size": 0.01, "build_ms": 1.0, "lookup_ms": 1.0, **more}


def _oracle(scene, n=1000, **more):
    """A hand-made oracle record of one case."""
    return {"scene": scene, "unit": "m", "light": "directional", "contender": "oracle", "n_receivers": n,
            "world_objective": 0.05, "texel_objective": 0.05, "per_texel_objective": 0.0, **more}


def _result(cases, suite="dsm-bench-1") -> dict:
    """A hand-made results.json document of ``cases``."""
    return {"suite": suite, "suite_sha256": "0" * 64, "size": "test", "dsm_version": "0", "variant": "x",
            "versions": {"dsm_git_commit": "c"}, "machine": {"cpu": "cpu", "cores": 1}, "cases": cases}


@pytest.mark.slow
def test_the_benchmark_leaderboard_sorts_in_the_browser(tmp_path, browser):
    """dsm benchmark's leaderboard.html from the file system: the answer first, a click on the
    error-rate header twice orders the ranking rows by hand-made error rates, largest first, and
    its scale.png shows."""
    from dsm.benchmark import page as bench_page
    rates = {"a": 0.30, "b": 0.10, "c": 0.20}          # one case each at 1000 receivers
    cases = [_record("s", c, e) for c, e in rates.items()] + [_oracle("s")]
    path = bench_page.write_page(_result(cases), tmp_path)
    drv = browser
    drv.get(path.as_uri())
    assert drv.find_element("css selector", "p.answer").text.startswith("Ranking")
    table = drv.find_elements("css selector", "table.sortable")[0]
    head = [th for th in table.find_elements("css selector", "thead th") if th.text.startswith("error rate")][0]
    head.click()
    head.click()
    order = drv.execute_script("return Array.from(arguments[0].tBodies[0].rows).map(r => r.cells[1].textContent)",
                               table)
    assert order == ["a", "c", "b"]
    # the scale figure beside the page loads from the file system (a broken link has no natural width)
    assert drv.execute_script("const i = document.querySelector('img[src=\"scale.png\"]');"
                              "return i !== null && i.complete && i.naturalWidth > 400")


LAYOUT_JS = """
const out = {pageWidth: document.documentElement.scrollWidth, window: window.innerWidth, overflow: []};
const body = document.body.getBoundingClientRect();
// every box the page lays out: none reaches past the body's right edge (wide content scrolls inside its box)
for (const e of document.querySelectorAll('section, h1, h2, p, .wide, .scroll, .figbox, .filters, figure, #viewer')) {
  if (e.closest('#zoom') || e.offsetParent === null) continue;
  const r = e.getBoundingClientRect();
  if (r.right > body.right + 1) out.overflow.push(e.tagName + '#' + (e.id || e.className) + ' ' + r.right);
}
return out;
"""


@pytest.mark.parametrize("width", [1280, 820])
def test_the_report_fits_its_window_and_its_plots_read_at_9_points(page, width):
    """At each window width: no box runs past the page's edge, the summary shows every row (no
    fixed-height box), every image loads, the tables' text is at least 9 points (12 CSS px) and every
    figure is shown at its pixel size, so its smallest text (figures.MIN_FONT points at figures.DPI)
    reads at 9 points or more."""
    from dsm.report import figures
    res, drv = page
    drv.set_window_size(width, 900)
    drv.get((res.out / "report.html").as_uri())
    assert all_images_loaded(drv) == []
    layout = drv.execute_script(LAYOUT_JS)
    assert layout["overflow"] == [] and layout["pageWidth"] <= layout["window"]
    box = drv.execute_script("const b = document.querySelector('#summary-table').parentElement;"
                             "return [b.scrollHeight, b.clientHeight, document.querySelectorAll('#summary-table tbody tr').length]")
    assert box[0] <= box[1] and box[2] == 4
    px = drv.execute_script("return ['#summary-table td', '#case-table td', '.plots figcaption', '.note']"
                            ".map(s => parseFloat(getComputedStyle(document.querySelector(s)).fontSize))")
    assert min(px) >= 12, px                                # 12 CSS px = 9 points
    shown = drv.execute_script("return Array.from(document.querySelectorAll('.plots img'))"
                               ".map(i => [i.clientWidth, i.naturalWidth])")
    assert shown and all(w == n for w, n in shown), shown
    # MIN_FONT points at DPI are MIN_FONT * DPI / 72 image pixels, shown one a CSS pixel (0.75 point)
    assert figures.MIN_FONT * figures.DPI / 72 * 0.75 >= 9


def test_a_point_of_a_pareto_plot_names_its_case_and_opens_it(page):
    """The pareto figure's image map: each area sits on a case's point (the case's time and error
    rate, from metrics.csv), its title names the case, and a click shows the case's images."""
    res, drv = page
    drv.set_window_size(1280, 900)
    drv.get((res.out / "report.html").as_uri())
    rows = {r["case"]: r for r in _csv(res)}
    areas = drv.execute_script("return Array.from(document.querySelectorAll('map[name^=pts-pareto] area'))"
                               ".map(a => [a.getAttribute('href'), a.title])")
    scored = [c for c, r in rows.items() if r["error_rate"] != ""]
    assert sorted(h.removeprefix("#case-") for h, _ in areas) == sorted(scored)
    assert all(t.startswith(f"case {h.removeprefix('#case-')}: {rows[h.removeprefix('#case-')]['scheme']}")
               for h, t in areas)
    href = areas[-1][0]
    drv.execute_script("document.querySelector(`area[href='${arguments[0]}']`).click()", href)
    case = href.removeprefix("#case-")
    assert drv.find_element("css selector", "#viewer p").text.startswith(f"case {case}:")
    assert drv.find_element("css selector", "#case-table tr.sel").get_attribute("data-case") == case


@pytest.mark.slow
def test_the_leaderboard_filters_and_fits(tmp_path, browser):
    """leaderboard.html at two widths: nothing runs past the page's edge, the scale figure loads at its
    pixel size; the family filter keeps the pre-filtered maps' rows alone (kind as the first word, by
    hand), the scene filter the cases of that scene, a ranking row's click its contender's cases."""
    from dsm.benchmark import page as bench_page
    cases = []
    for scene in ("s", "t"):
        for c, e in {"vsm box:5": 0.30, "bevy": 0.10, "receiver_plane": 0.20}.items():
            cases.append(_record(scene, c, e, params="bias=5.96046e-08 range"))
        cases.append(_oracle(scene))
    path = bench_page.write_page(_result(cases), tmp_path)
    drv = browser
    from selenium.webdriver.support.ui import Select
    for width in (1280, 820):
        drv.set_window_size(width, 900)
        drv.get(path.as_uri())
        assert all_images_loaded(drv) == []
        layout = drv.execute_script(LAYOUT_JS)
        assert layout["overflow"] == [] and layout["pageWidth"] <= layout["window"]
        img = drv.execute_script("const i = document.querySelector('img[src=\"scale.png\"]');"
                                 "return [i.clientWidth, i.naturalWidth]")
        assert img[0] == img[1]
    visible = lambda table: drv.execute_script(
        f"return Array.from(document.querySelectorAll('#{table} tbody tr')).filter(r => !r.hidden)"
        ".map(r => [r.dataset.contender, r.dataset.scene])")
    visible_pairs = lambda table: [tuple(x) for x in visible(table)]
    Select(drv.find_element("css selector", ".filters select[name=family]")).select_by_value("pre-filtered map")
    assert [c for c, _ in visible("ranking")] == ["vsm box:5"]
    Select(drv.find_element("css selector", ".filters select[name=family]")).select_by_value("")
    Select(drv.find_element("css selector", ".filters select[name=scene]")).select_by_value("t")
    assert sorted(visible_pairs("case-list")) == sorted((c["contender"], "t") for c in cases
                                                  if c["scene"] == "t" and c["contender"] != "oracle")
    assert drv.find_element("id", "case-list-shown").text == "3"
    drv.execute_script("document.querySelector('#ranking tbody tr[data-contender=\"bevy\"]').click()")
    assert visible_pairs("case-list") == [("bevy", "t")]
    # the parameters read as a power of two, the exact text in results.json
    assert "bias=2^-24 range" in drv.find_element("id", "case-list").text


@pytest.fixture(scope="module")
def grad_page(tiny_grad_run, chromium):
    """dsm grad --compare --inverse's report.html (a tiny plate, helpers_grad.TINY) in the shared Chromium."""
    return tiny_grad_run, chromium


@pytest.mark.slow
@pytest.mark.parametrize("width", [1280, 820])
def test_the_grad_report_fits_its_window_and_reads_at_9_points(grad_page, width):
    """dsm grad's report.html at each width: nothing runs past the page's edge, every figure loads and is
    shown at its pixel size (its MIN_FONT text at DPI reads at 9 points), every text is 12 CSS px or more,
    and no request leaves the file system."""
    out, drv = grad_page
    drv.set_window_size(width, 900)
    drv.get((out / "report.html").as_uri())
    assert all_images_loaded(drv) == []
    layout = drv.execute_script(LAYOUT_JS)
    assert layout["overflow"] == [] and layout["pageWidth"] <= layout["window"]
    shown = drv.execute_script("return Array.from(document.querySelectorAll('.plots img'))"
                               ".map(i => [i.getAttribute('src'), i.clientWidth, i.naturalWidth])")
    assert [s for s, _, _ in shown] == ["relative_error.png", "gradients.png", "inverse.png"]
    assert all(w == n for _, w, n in shown), shown
    px = drv.execute_script("return ['td', 'th', '.note', '.answer', 'figcaption', 'h3']"
                            ".map(s => Math.min(...Array.from(document.querySelectorAll(s))"
                            ".map(e => parseFloat(getComputedStyle(e).fontSize))))")
    assert min(px) >= 12, px
    assert drv.execute_script("return Array.from(document.querySelectorAll('[src],[href]'))"
                              ".every(e => !/^https?:/.test(e.getAttribute('src') || e.getAttribute('href')))")


@pytest.mark.slow
def test_clicking_the_grad_reports_rel_error_header_orders_its_rows(grad_page):
    """compare.csv's table sorted by rel_error in the browser: the CSV's values in order, undefined last."""
    out, drv = grad_page
    drv.set_window_size(1280, 900)
    drv.get((out / "report.html").as_uri())
    rows = list(csv.DictReader(open(out / "compare.csv")))
    head = next(th for th in drv.find_elements("css selector", "#table-compare thead th") if th.text == "rel_error")
    drv.execute_script("arguments[0].scrollIntoView()", head)
    head.click()
    got = drv.execute_script("return Array.from(document.querySelectorAll('#table-compare tbody tr'))"
                             ".map(r => [r.cells[0].textContent, r.cells[1].textContent])")
    key = lambda r: (r["rel_error"] == "", float(r["rel_error"]) if r["rel_error"] else 0.0)
    want = [[r["technique"], r["param"]] for r in sorted(rows, key=key)]
    assert got == want and want != [[r["technique"], r["param"]] for r in rows]


@pytest.mark.slow
def test_a_contender_page_fits_loads_its_images_and_orders_its_cases_worst_first(tmp_path, browser):
    """A contender's page from a hand-made result and its case images: the leaderboard's contender name
    opens it; at two widths nothing runs past the page's edge and every image loads, shown at
    contenders.SHOWN_PX; its cards come worst error rate first, and 'worst FLIP first' orders them by
    the FLIP values given by hand (a case whose error rate is undefined last)."""
    import numpy as np
    from dsm.benchmark import case_images, contenders, page as bench_page
    rng = np.random.default_rng(5)
    given = {"s": (0.10, 0.02), "t": (0.30, 0.01), "u": (0.20, 0.05), "v": (float("nan"), 0.03)}
    cases = []
    for scene, (err, flip) in given.items():
        n = 0 if err != err else 1000
        for c in ("bevy", "three"):
            cases.append(_record(scene, c, err, n, offset="0", light="spot", n_gt_shadowed=n // 2,
                                 peterpan_rate=0.0 if n else err, flip=flip, params=""))
        case_images.keep(tmp_path, cases[-2:], [(rng.integers(0, 8, (24, 24)).astype(np.uint8),
                                                  rng.random((24, 24)).astype(np.float32)) for _ in range(2)])
        cases.append(_oracle(scene, n, offset="0", light="spot"))
    board = bench_page.write_page(_result(cases, "dsm-bench-5"), tmp_path)
    cards = lambda: drv.execute_script("return Array.from(document.querySelectorAll('#cards > figure.case'))"
                                       ".map(f => f.querySelector('figcaption').textContent.split(',')[0])")
    drv = browser
    drv.get(board.as_uri())
    drv.find_element("css selector", "#ranking a[href='contenders/bevy.html']").click()
    assert drv.current_url == (tmp_path / contenders.page_path("bevy")).as_uri()
    for width in (1280, 820):
        drv.set_window_size(width, 900)
        drv.get((tmp_path / contenders.page_path("bevy")).as_uri())
        assert all_images_loaded(drv) == []
        layout = drv.execute_script(LAYOUT_JS)
        assert layout["overflow"] == [] and layout["pageWidth"] <= layout["window"]
        # each image its case's sheet (two records, 24 px squares) cut to the record's square
        shown = drv.execute_script("return Array.from(document.querySelectorAll('#cards img')).map(i => "
                                   "[i.clientWidth, i.naturalWidth, i.naturalHeight, i.parentElement.clientHeight])")
        assert shown == [[contenders.SHOWN_PX, 24, 48, contenders.SHOWN_PX]] * 8
    assert cards() == ["t", "u", "s", "v"]                      # error rate 0.3, 0.2, 0.1, undefined
    assert "undefined" in drv.find_element("css selector", "#cards > figure.case:last-child").text
    drv.find_element("css selector", ".order button[data-key=flip]").click()
    assert cards() == sorted(given, key=lambda s: -given[s][1]) == ["u", "v", "s", "t"]
