"""The documentation: the config reference's keys are the reader's keys, the site builds offline with
warnings as errors, its internal links resolve, its how-to configs load, README's commands exist."""
import importlib
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from dsm.config import keys as keymod, read

ROOT = Path(__file__).resolve().parents[1]

# a config that reaches every hand-read table, beside the shipped experiments
EVERY_TABLE = """
[experiment]
name = "every_table"
seed = 3
variant = "llvm_ad_rgb"
[camera]
resolution = [32, 32]
position = [3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40
near = 0.01
far = 100.0
[[scene]]
builtin = "plane_box"
[[light]]
type = "spot"
position = [-2.0, 2.5, 2.6]
target = [0.0, 0.0, 0.0]
[[light]]
type = "point"
position = [0.6, -0.8, 2.2]
[map]
resolution = 64
[memory]
budget_mb = 512
[timing]
repeats = 1
[oracle]
lambda = 1.0
[report]
images = "none"
[execution]
backend = "ray"
address = "local"
[[motion]]
frames = 2
camera = "keyframes"
keys = [{position = [3.0, -3.0, 2.0], target = [0.0, 0.0, 0.0]}, {position = [3.0, -2.0, 2.0], target = [0.0, 0.0, 0.0]}]
light = "keyframes"
light_keys = [{position = [-2.0, 2.5, 2.6]}, {position = [-2.0, 2.0, 2.6]}]
[[scheme]]
name = "constant"
[tune]
steps = 2
[[tune.camera]]
position = [3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
[[tune.camera]]
position = [-3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
role = "heldout"
[tune.bias_map]
fit = "edge"
"""


def _table_of(where: str) -> str:
    """The reference's table name of a reader's ``where`` ('light[2]' -> 'light', 'motion[0].keys[1]' ->
    'motion.keys', '' -> the top level)."""
    return re.sub(r"\[\d+\]", "", where)


def accepted_keys(monkeypatch) -> dict:
    """{table: keys the reader accepts there}, recorded from its own check_keys calls over every
    shipped experiment and EVERY_TABLE (a table read by several light types: their union)."""
    seen = {}
    real = read.check_keys

    def recording(table, allowed, source, where):
        seen.setdefault(_table_of(where), set()).update(allowed)
        return real(table, allowed, source, where)
    for name in ("dsm.config.read", "dsm.config.tune", "dsm.core.types", "dsm.lights.spot", "dsm.lights.scene",
                 "dsm.lights.directional", "dsm.lights.point", "dsm.lights.area", "dsm.config.virtual",
                 "dsm.grad.spec"):
        monkeypatch.setattr(importlib.import_module(name), "check_keys", recording)
    for path in sorted((ROOT / "experiments").glob("*.toml")):
        read.load(path)
    from dsm.grad import spec as grad_spec        # [gradient]: dsm grad's configs
    for path in sorted((ROOT / "experiments" / "gradient").glob("*.toml")):
        grad_spec.load(path)
    read.parse(tomllib.loads(EVERY_TABLE), "<every table>")
    return seen


@pytest.mark.slow
def test_config_reference_is_the_readers_keys(monkeypatch):
    """Every key the reader accepts in a hand-read table is declared in dsm.config.keys, and every
    declared key is one the reader accepts (tables read into dataclasses are documented from them)."""
    seen = accepted_keys(monkeypatch)
    top = seen.pop("")
    assert set(top) == set(read.TOP_KEYS)
    for table in keymod.TABLES:
        declared = {k.name for k in keymod.keys_of(table)}
        if table in ("scene", "scheme", "contact"):     # their other keys are a dataclass's fields
            continue
        assert table in seen, f"no config reached [{table}]"
        assert seen[table] == declared, (table, sorted(seen[table] ^ declared))


def test_config_reference_defaults_are_the_readers():
    """The declared defaults of [timing], [report], [oracle], [map] and [experiment] are what the reader
    gives a config that leaves them out."""
    cfg = read.parse({"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]}, "<min>")
    want = {("timing", "repeats"): str(cfg.timing_repeats), ("timing", "lookups"): cfg.timing_lookups,
            ("timing", "builds"): cfg.timing_builds, ("report", "images"): cfg.report_images,
            ("oracle", "lambda"): f"{cfg.oracle.lambdas[0]:g}", ("experiment", "seed"): str(cfg.seed),
            ("map", "resolution"): str(cfg.map.resolution[0]), ("map", "filter"): cfg.map.filter[0],
            ("map", "format"): cfg.map.format[0], ("map", "view"): cfg.map.view[0],
            ("map", "kind"): cfg.map.kind[0], ("map", "leak_texels"): f"{cfg.map.leak_texels:g}"}
    declared = {(k.table, k.name): k.default for k in keymod.KEYS}
    assert {key: declared[key] for key in want} == want


# ---------------------------------------------------------------- the site

sys.path.insert(0, str(ROOT / "docs" / "_ext"))
from links import broken_links            # noqa: E402  (docs/_ext is the site's tooling, not a package)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built as scripts/docs builds it (offline, warnings as errors) into a fresh folder."""
    out = tmp_path_factory.mktemp("site")
    run = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
                          str(ROOT / "docs"), str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-4000:]
    return out


@pytest.mark.slow
def test_site_builds_and_every_internal_link_resolves(site):
    """sphinx-build -W passed (the fixture) and no href or src of any page leads nowhere."""
    assert (site / "index.html").is_file()
    assert broken_links(site) == []


def test_link_check_finds_a_broken_link_and_a_missing_anchor(tmp_path):
    """The checker itself: a missing file and a missing id are found; a present one and a URL are not."""
    (tmp_path / "a.html").write_text('<p id="here"><a href="b.html#gone">x</a><a href="a.html#here">y</a>'
                                     '<a href="https://example.org/x">z</a><img src="missing.png"></p>')
    (tmp_path / "b.html").write_text('<p id="there"></p>')
    assert broken_links(tmp_path) == [("a.html", "b.html#gone"), ("a.html", "missing.png")]


@pytest.mark.slow
def test_site_has_every_page_it_promises(site):
    """Tutorials (every notebook), how-to guides, the three generated references, design topics (every
    ## heading of docs/design.md) and every docs/*.md page, picked up by the globs."""
    notebooks = sorted(p.stem for p in (ROOT / "notebooks").glob("*.ipynb"))
    assert sorted(p.stem for p in (site / "_generated" / "tutorials").glob("*.html")) == notebooks
    headings = re.findall(r"(?m)^## (.+)$", (ROOT / "docs" / "design.md").read_text())
    assert len(list((site / "_generated" / "design").glob("*.html"))) == len(headings) + 1   # + overview
    for page in sorted((ROOT / "docs").glob("*.md")) + sorted((ROOT / "docs" / "howto").glob("*.md")):
        assert (site / page.relative_to(ROOT / "docs")).with_suffix(".html").is_file(), page
    for ref in ("config", "cli", "schemes"):
        assert (site / "_generated" / "reference" / f"{ref}.html").is_file()


@pytest.mark.slow
def test_notebooks_show_their_stored_outputs(site):
    """A tutorial page holds as many images as its notebook's stored image outputs (not run again)."""
    import json
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb"))[:3]:
        cells = json.loads(nb.read_text())["cells"]
        stored = sum("image/png" in o.get("data", {}) for c in cells for o in c.get("outputs", []))
        html = (site / "_generated" / "tutorials" / f"{nb.stem}.html").read_text()
        assert len(re.findall(r"<img [^>]*src=\"[^\"]*\.png\"", html)) >= stored > 0, nb.name


def test_generated_references_name_every_key_scheme_and_command():
    """The config page names every declared key, the schemes page every registered scheme and preset,
    the CLI page every subcommand: generated from the code, nothing hand-copied."""
    import generate
    from dsm import cli, schemes
    from dsm.schemes import presets
    config = generate.config_reference()
    for k in keymod.KEYS:
        assert f"`{k.name}`" in config.split(f"[{k.table}]", 1)[1], (k.table, k.name)
    page = generate.schemes_reference()
    assert all(f"## {s.NAME}\n" in page for s in schemes.ALL) and all(f"`{n}`" in page for n in presets.names())
    commands = [name for name, _ in generate.subparsers(cli.parser())]
    assert {"run", "report", "plan", "schemes", "perf", "tune", "benchmark"} <= set(commands)
    assert all(f"## dsm {c}\n" in generate.cli_reference() for c in commands)


HOWTO_TOML = re.compile(r"```toml\n(.*?)```", re.S)


def test_howto_configs_load():
    """Every TOML block of a how-to guide and of README.md is a config dsm accepts (paths relative to
    the checkout)."""
    pages = sorted((ROOT / "docs" / "howto").glob("*.md")) + [ROOT / "README.md"]
    blocks = [(p.name, b) for p in pages for b in HOWTO_TOML.findall(p.read_text())]
    assert len(blocks) >= 5
    for name, block in blocks:
        read.parse(tomllib.loads(block), name, base=ROOT)


def test_readme_is_a_front_door():
    """README.md: about 150 lines; its set-up commands exist and are executable (.ci/run runs
    scripts/test, the README's test command); every local link it gives resolves."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 170
    for cmd in ("scripts/run-default", "scripts/test", "scripts/docs"):
        assert cmd in text and (ROOT / cmd).stat().st_mode & 0o111, cmd
    assert "scripts/test" in (ROOT / ".ci" / "run").read_text()
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
        assert (ROOT / target).exists(), target


@pytest.mark.parametrize("key, good, bad", [("steps", 256, 257), ("jitter", 1.0, 1.01)])
def test_contact_bounds_are_the_readers(key, good, bad):
    """The reference's upper bounds of [contact] steps and jitter are where the reader starts refusing."""
    assert keymod.contact_bounds()[key].endswith(f"to {good:g}")
    base = {"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]}
    read.parse({**base, "contact": {key: good}}, "<c>")
    with pytest.raises(read.ConfigError, match=f"contact.{key}"):
        read.parse({**base, "contact": {key: bad}}, "<c>")


# ---------------------------------------------------------------- the site in a browser (issue 75)

@pytest.fixture(scope="module")
def browser():
    """Headless Chromium (conftest.chrome) at 1280 x 900, one for the module's page tests (a start
    each cost a second or more), quit after the last."""
    from conftest import chrome
    drv = chrome()
    drv.set_window_size(1280, 900)
    yield drv
    drv.quit()


def _site_page(drv, site, path: str):
    """``drv`` on one built page, once the page says it is laid out."""
    from selenium.webdriver.support.ui import WebDriverWait
    drv.get((site / path).as_uri())
    # the page's scripts may still be laying out the sidebar when get() returns: wait for the document
    # to say it is complete (a condition, not a sleep)
    WebDriverWait(drv, 120).until(lambda d: d.execute_script("return document.readyState") == "complete"
                                  and d.execute_script("return document.querySelector('.sidebar-tree') !== null"))
    return drv


@pytest.mark.slow
def test_the_sidebar_is_in_a_newcomers_order(site, browser):
    """Start here first (install, first run, own scene, reading the report), then tutorials, how-tos,
    reference, topics, results, and the design as one entry."""
    drv = _site_page(browser, site, "index.html")
    captions = drv.execute_script("return Array.from(document.querySelectorAll('.sidebar-tree p.caption'))"
                                  ".map(p => p.textContent.trim())")
    assert captions == ["Start here", "Tutorials", "How-to guides", "Reference", "Topics", "Results", "Design"]
    first = drv.execute_script("const l = document.querySelectorAll('.sidebar-tree ul')[0];"
                               "return Array.from(l.children).map(li => li.querySelector('a').getAttribute('href'))")
    assert first[:4] == ["install.html", "running.html", "howto/my_own_scene.html", "report-figures.html"]
    design = drv.execute_script(
        "const ul = Array.from(document.querySelectorAll('.sidebar-tree p.caption')).pop().nextElementSibling;"
        "const inner = ul.querySelector(':scope > li > ul');"
        "return [ul.querySelectorAll(':scope > li').length, inner !== null, inner && inner.offsetParent !== null]")
    assert design == [1, True, False]          # one entry, its topics folded under it


@pytest.mark.slow
def test_tutorial_01s_first_output_is_an_html_table_and_its_plumbing_is_out_of_sight(site, browser):
    drv = _site_page(browser, site, "_generated/tutorials/01_quick_start.html")
    first = drv.execute_script("const o = document.querySelector('.cell_output');"
                               "return [o.querySelector('table') !== null, o.querySelectorAll('tbody tr').length,"
                               " o.innerText]")
    assert first[0] and first[1] == 5, first             # the five schemes of its config, one row each
    assert "| scheme |" not in first[2] and "normal_offset" in first[2]
    assert "DSM_NOTEBOOK_SMALL" not in drv.find_element("css selector", "article").text


@pytest.mark.slow
def test_the_api_reference_documents_the_run_the_results_and_every_testing_function(site, browser):
    """Each a visible entry on the API page whose text holds its docstring's first words (autodoc)."""
    import inspect
    import dsm
    import dsm.testing
    from dsm.experiment.results import Results
    wanted = {"dsm.run": dsm.run, "dsm.experiment.results.Results.where": Results.where}
    wanted |= {f"dsm.testing.{n}": f for n, f in vars(dsm.testing).items()
               if inspect.isfunction(f) and f.__module__ == "dsm.testing" and not n.startswith("_")}
    assert len(wanted) == 5
    drv = _site_page(browser, site, "api.html")
    for name, obj in wanted.items():
        text = drv.execute_script("const d = document.getElementById(arguments[0]);"
                                  "return d && d.offsetParent !== null ? d.parentElement.innerText : null", name)
        first = " ".join(inspect.getdoc(obj).replace("``", "").split()[:4])
        assert text is not None and first in " ".join(text.split()), (name, first, text)


@pytest.mark.slow
def test_every_scheme_has_its_page_with_its_image(site, browser):
    """A page per registered scheme, titled by its name, showing its own error image (loaded)."""
    from dsm import schemes
    drv = _site_page(browser, site, "_generated/schemes/index.html")
    for s in schemes.ALL:
        drv.get((site / "_generated" / "schemes" / f"{s.NAME}.html").as_uri())
        h1, imgs = drv.execute_script(
            "return [document.querySelector('article h1').textContent,"
            " Array.from(document.querySelectorAll('article img')).map(i => [i.getAttribute('src'),"
            " i.complete && i.naturalWidth > 0])]")
        assert h1.startswith(s.NAME), h1
        assert [ok for src, ok in imgs if src.endswith(f"/{s.NAME}.png")] == [True], (s.NAME, imgs)
