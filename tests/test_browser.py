"""report.html in a real browser: headless Chromium driven by Selenium (Debian's chromium and
chromium-driver, which scripts/setup installs when it runs as root). Opened from the file system,
it shows the summary and the case table in the live DOM, and a click on the acne-rate header
orders the rows as metrics.csv's values say."""
import csv
import math
import shutil

import pytest

from conftest import base_config


def _chrome():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.skip("selenium is not installed (pip install -e .[test])")
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not browser or not driver:
        pytest.skip("Chromium or its driver is missing (as root: apt-get install chromium chromium-driver; "
                    "scripts/test does it)")
    opts = Options()
    opts.binary_location = browser
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1280,900",
              "--allow-file-access-from-files"):
        opts.add_argument(a)
    try:
        return webdriver.Chrome(service=Service(driver), options=opts)
    except Exception as e:       # a browser that cannot start here: say why, do not fail the suite
        pytest.skip(f"Chromium did not start: {str(e).splitlines()[0]}")


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    import dsm
    cfg = base_config(experiment={"name": "browser"}, camera={"resolution": [32, 32]},
                      scene=[{"builtin": "plane"}, {"builtin": "plane_box"}], map={"resolution": [16, 32]},
                      scheme=[{"name": "none"}, {"name": "constant", "bias": ["1 texel", 0.05]}, {"name": "adaptive"}])
    res = dsm.run(cfg, out=tmp_path_factory.mktemp("browser") / "run")
    drv = _chrome()
    drv.get((res.out / "report.html").as_uri())
    yield res, drv
    drv.quit()


def _csv(res):
    with open(res.out / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _visible_cases(drv):
    return drv.execute_script("return Array.from(document.querySelectorAll('#case-table tbody tr'))"
                              ".filter(r => !r.hidden).map(r => r.dataset.case)")


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
    assert [i.get_attribute("alt") for i in imgs] == [f"error image of case {case}", f"shadow image of case {case}",
                                                      f"shading (tinted) of case {case}",
                                                      f"error classes (tinted) of case {case}"]
    assert [c.text for c in drv.find_elements("css selector", "#viewer figcaption")] == [
        "error classes (colours below)", "shading under the shadow map (Lambert, ambient in shadow)",
        "error classes tinted over the shading"]
    # the images load from the file system (a broken link has no natural width)
    loaded = drv.execute_script("const im = Array.from(document.querySelectorAll('#viewer img'));"
                                "return im.every(i => i.complete && i.naturalWidth === 32)")
    assert loaded


def test_the_benchmark_leaderboard_sorts_in_the_browser(tmp_path):
    """dsm benchmark's leaderboard.html from the file system: the answer first, a click on the
    error-rate header twice orders the ranking rows by hand-made error rates, largest first, and
    its scale.png shows."""
    from dsm.benchmark import page as bench_page
    rates = {"a": 0.30, "b": 0.10, "c": 0.20}          # one case each at 1000 receivers
    cases = [{"scene": "s", "unit": "m", "light": "directional", "contender": c, "n_receivers": 1000,
              "n_acne": int(e * 1000), "n_peterpan": 0, "acne_rate": e, "peterpan_rate": 0.0, "error_rate": e,
              "texel_size": 0.01, "build_ms": 1.0, "lookup_ms": 1.0} for c, e in rates.items()]
    cases.append({"scene": "s", "unit": "m", "light": "directional", "contender": "oracle", "n_receivers": 1000,
                  "world_objective": 0.05, "texel_objective": 0.05, "per_texel_objective": 0.0})
    doc = {"suite": "dsm-bench-1", "suite_sha256": "0" * 64, "size": "test", "dsm_version": "0", "variant": "x",
           "versions": {"dsm_git_commit": "c"}, "machine": {"cpu": "cpu", "cores": 1}, "cases": cases}
    path = bench_page.write_page(doc, tmp_path)
    drv = _chrome()
    try:
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
    finally:
        drv.quit()
