import ast
import csv
import functools
import json
import os
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT / "data" / "meshes"          # the real test meshes, shipped with the kit (data/meshes/README.md)
# metrics.csv's columns that differ between runs by nature (timings, peak memory, compile counts);
# every other column is compared when two runs must agree
VARYING = {"build_ms", "build_first_ms", "build_compile_ms", "build_peak_mb", "lookup_ms", "lookup_compile_ms",
           "lookup_kernels_compiled", "reference_ms", "fit_ms"}


@pytest.fixture(scope="session", autouse=True)
def variant():
    """One variant for the session (llvm_ad_rgb unless DSM_VARIANT says otherwise)."""
    from dsm.core import env
    v = env.use_variant(os.environ.get("DSM_VARIANT"), threads=worker_threads())
    yield v
    import drjit as dr
    dr.sync_thread()
    dr.flush_kernel_cache()
    dr.flush_malloc_cache()


# ------------------------------------------------ pytest-xdist (scripts/test runs -n <cores> --dist loadgroup)
# A module- or class-scoped fixture is built once per worker process, so the tests that take one of
# their own file's are one xdist group: one worker builds it once (a documentation site, a benchmark
# run), instead of each worker that gets one of them. The groups are found from the files' source in
# the scheduler, not by adding xdist_group marks at collection: pytest 9.2's node ids ignore the
# suffix through which xdist 3.8 sends such marks to the scheduler (pytest-xdist issue 1386).

def fixture_decorator(node) -> tuple | None:
    """(name, scope, autouse) of a ``@pytest.fixture(...)`` function definition, or None."""
    for dec in node.decorator_list:
        call = dec if isinstance(dec, ast.Call) else None
        func = call.func if call else dec
        if (isinstance(func, ast.Attribute) and func.attr == "fixture") or (isinstance(func, ast.Name)
                                                                            and func.id == "fixture"):
            kw = {k.arg: k.value.value for k in (call.keywords if call else []) if isinstance(k.value, ast.Constant)}
            return kw.get("name", node.name), kw.get("scope", "function"), bool(kw.get("autouse", False))
    return None


@functools.lru_cache(maxsize=None)
def shared_fixture_users(path: Path) -> frozenset:
    """The test functions of the file ``path`` that take (directly or through another fixture of the
    file) a module- or class-scoped fixture the file defines; every test where such a fixture is autouse."""
    try:
        tree = ast.parse(path.read_text())
    except (OSError, SyntaxError, ValueError):
        return frozenset()
    functions = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    takes = lambda n: {a.arg for a in n.args.args + n.args.kwonlyargs}
    fixtures = {f[0]: (f, takes(n)) for n in functions if (f := fixture_decorator(n))}
    shared = {name for name, ((_, scope, _), _) in fixtures.items() if scope in ("module", "class")}
    autouse = any(auto and name in shared for name, ((_, _, auto), _) in fixtures.items())
    grew = True
    while grew:                        # a function fixture that takes a shared one shares it
        more = {name for name, (_, args) in fixtures.items() if args & shared} - shared
        shared |= more
        grew = bool(more)
    tests = {n.name: takes(n) for n in functions if n.name.startswith("test")}
    return frozenset(t for t, args in tests.items() if autouse or args & shared)


def worker_threads() -> int | None:
    """Dr.Jit's threads in a pytest-xdist worker: this process's CPUs shared out among the workers (at
    least one), or None outside xdist (Dr.Jit's own default, one per CPU). Two workers with a thread per
    CPU each spent more CPU on a 180-test subset than with one each, and mostly took longer (DEVELOPERS.md,
    *Tests*); results do not depend on the thread count (docs/design.md: nor on tiling)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or 0)
    if not os.environ.get("PYTEST_XDIST_WORKER") or workers < 1:
        return None
    return max(1, len(os.sched_getaffinity(0)) // workers)


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist, the tests marked slow first (in their order): after the groups, the scheduler
    hands out tests in collection order, and a minute-long test started last leaves the other workers idle."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        slow = lambda item: item.get_closest_marker("slow") or item.get_closest_marker("dsm_slow")
        items.sort(key=lambda item: slow(item) is None)     # stable: ties keep their order


@pytest.hookimpl(optionalhook=True)   # a hook of pytest-xdist's: without it installed, nothing asks
def pytest_xdist_make_scheduler(config, log):
    """--dist loadgroup's scheduler, the tests sharing a module- or class-scoped fixture of their file
    made one group (named after the file); an xdist_group mark groups too where xdist can see it (under
    pytest before 9.2)."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class SharedFixtureScheduling(LoadGroupScheduling):
        """LoadGroupScheduling, with a group per file for the users of its shared fixtures."""

        def _split_scope(self, nodeid: str) -> str:
            path, _, rest = nodeid.partition("::")
            test = rest.split("::")[-1].split("[")[0]
            if "@" not in nodeid and test in shared_fixture_users(config.rootpath / path):
                return f"{path}@shared-fixtures"
            return super()._split_scope(nodeid)
    return SharedFixtureScheduling(config, log)


def base_config(**over):
    """A small experiment as a dict; keyword tables replace the defaults."""
    cfg = {"experiment": {"name": "test"}, "camera": {"resolution": [192, 192]},
           "scene": [{"builtin": "plane"}], "map": {"resolution": 128},
           "scheme": [{"name": "none"}], "timing": {"repeats": 1}}
    cfg.update(over)
    return cfg


@pytest.fixture
def run_dict(tmp_path):
    import dsm

    def _run(cfg, name="out", report=False):
        # without the report unless a test reads it: the figures are half of a small run's time
        return dsm.run(cfg, out=tmp_path / name, report=report)
    return _run


def assert_nan_only_where_undefined(row):
    """Every float of a result row is finite, except the values whose definition has an empty
    denominator (DESIGN: undefined, NaN in Python, an empty cell in metrics.csv)."""
    import math
    seams = row["view"] not in ("orthographic", "perspective")
    undefined = {
        "acne_rate": row["n_gt_lit"] == 0, "peterpan_rate": row["n_gt_shadowed"] == 0,
        "error_rate": row["n_receivers"] == 0, "mean_abs_error": row["n_receivers"] == 0,
        "texel_size": row["n_receivers"] == 0, "peterpan_dist_median": row["n_peterpan"] == 0,
        "f32_step": row["n_receivers"] == 0, "texel_f32_steps": row["n_receivers"] == 0,
        "n_seam": not seams, "seam_error_rate": not seams or row["n_seam"] == 0,
        "off_seam_error_rate": not seams or row["n_seam"] == row["n_receivers"],
        "backface_lit_rate": row["n_backfacing"] == 0,
        "n_plane_fallback": row["scheme"] not in ("receiver_plane", "adaptive"),
        **{k: row["filter"] != "nearest" for k in ("n_acne_resolution", "n_acne_bias", "n_peterpan_resolution",
                                                   "n_peterpan_bias")},
    }
    for k, v in row.items():
        if isinstance(v, float):
            if undefined.get(k, False):
                assert math.isnan(v), (row["case"], k, v)
            else:
                assert math.isfinite(v), (row["case"], k, v)


def cli_run(capsys, *args):
    """(exit status, non-blank stderr lines) of an in-process ``dsm`` call."""
    from dsm import cli
    capsys.readouterr()
    rc = cli.main([str(a) for a in args])
    return rc, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def one_line(err, *words):
    """``err`` is one line, no traceback, holding every one of ``words``."""
    assert len(err) == 1 and "Traceback" not in err[0], err
    for w in words:
        assert w in err[0], (w, err[0])


def write_toml(path: Path, cfg: dict) -> Path:
    """``cfg`` (tables of scalars, lists and tables; arrays of tables as lists) written to ``path`` as TOML."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    lines = []
    for name, table in cfg.items():
        for t in (table if isinstance(table, list) else [table]):
            lines.append(f"[[{name}]]" if isinstance(table, list) else f"[{name}]")
            lines += [f"{k} = {value(v)}" for k, v in t.items()]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


# ------------------------------------------------ shared by the input tests (test_*_inputs.py, test_lock.py, ...)

def tiny_toml(extra: str = "", scene: str = 'builtin = "plane"', name: str = "t") -> str:
    """A 32^2 experiment's TOML text (one scene, one scheme), ``extra`` appended."""
    return (f'[experiment]\nname = "{name}"\n[camera]\nresolution = [32, 32]\n[[scene]]\n{scene}\n'
            f'[map]\nresolution = 32\n[[scheme]]\nname = "none"\n[timing]\nrepeats = 1\n{extra}')


@pytest.fixture
def cfg_file(tmp_path):
    """tmp_path/c.toml holding ``tiny_toml()``."""
    path = tmp_path / "c.toml"
    path.write_text(tiny_toml())
    return path


def metrics_rows(folder: Path) -> list:
    """``folder``/metrics.csv's rows as dicts of strings."""
    with open(folder / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def small_run(tmp_path):
    """The Results of a 32^2 plane_box run with one constant bias, into tmp_path/r."""
    import dsm
    return dsm.run(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                               map={"resolution": 32}, scheme=[{"name": "constant"}]), out=tmp_path / "r",
                   report=False)


def write_cfg(tmp_path, raw) -> Path:
    """``raw`` (a config dict of tables and arrays of tables) as tmp_path/cfg.toml."""
    return write_toml(tmp_path / "cfg.toml", raw)


def toml_text(d: dict, prefix: str = "") -> str:
    """``d`` as TOML (scalars, lists of scalars, tables and arrays of tables): the config a user writes."""
    val = lambda v: ("true" if v else "false") if isinstance(v, bool) else repr(v) if not isinstance(v, str) else f'"{v}"'
    flat = lambda v: "[" + ", ".join(val(x) for x in v) + "]" if isinstance(v, list) else val(v)
    plain = {k: v for k, v in d.items() if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict))}
    out = [f"{k} = {flat(v)}" for k, v in plain.items()]
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out += [f"[{name}]", toml_text(v, name + ".")]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for t in v:
                out += [f"[[{name}]]", toml_text(t, name + ".")]
    return "\n".join(out) + "\n"


def folder_files(folder) -> dict:
    """Every file under ``folder`` with its bytes (the lock file aside): what a refusal must leave."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".dsm-lock"}


def cli_lines(capsys, *argv) -> tuple:
    """(exit status, stderr's lines, blank ones inside kept) of an in-process ``dsm argv``."""
    from dsm import cli
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err.strip().splitlines()


# ------------------------------------------------ what a test file may be named after (tests/test_test_names.py)
# A test file is tests/test_<module>[_more].py for a module or package of dsm/ or plugins/, or one of
# these topics, each with where it is documented: (a file or folder, the heading in it or None).
TEST_TOPICS = {
    "acne_surface": ("docs/design.md", "### The acne split: self or edge, by surface"),
    "browser": ("docs/design.md", "## Figures and pages a reader can read"),
    "docs": ("docs/design.md", "## The documentation site (`docs/`, `scripts/docs`)"),
    "experiments": ("experiments", None),
    "far_from_origin": ("docs/far_from_origin.md", None),
    "filters_formats": ("docs/design.md", "## Schemes"),
    "gpu": ("DEVELOPERS.md", "## The GPU check (cuda_ad_rgb against llvm_ad_rgb)"),
    "hard_cases": ("docs/benchmark.md", None),
    "imports": ("docs/design.md", "### Packages as layers"),
    "inputs": ("docs/running.md", None),
    "install": ("docs/install.md", None),
    "layers": ("docs/design.md", "## Layered maps: the cost of a second layer"),
    "machine_independence": ("docs/design.md", "## Results that do not depend on the machine"),
    "moving_casters": ("docs/moving_casters.md", None),
    "moving_virtual": ("docs/moving_casters.md", "## Virtual maps: a page cache"),
    "msm16": ("docs/design.md", "## Pre-filtered maps (`dsm/prefilter/`)"),
    "notebooks": ("notebooks", None),
    "papers": ("docs/papers.md", None),
    "physics": ("docs/design.md", "## Conventions"),
    "plugins": ("plugins/dsm_plugins", None),
    "real_meshes": ("data/meshes/README.md", None),
    "scheme_contract": ("docs/design.md", "## Schemes"),
    "scheme_pages": ("docs/design.md", "## The documentation site (`docs/`, `scripts/docs`)"),
    "sponza_model": ("docs/sponza.md", None),
    "stable_answer": ("docs/design.md", "## What accuracy costs: costs in counts, the frontier, the answer"),
    "test_names": ("DEVELOPERS.md", "## Tests"),
    "trust": ("docs/design.md", "## Results that do not depend on the machine"),
    "versions": ("docs/design.md", "## Installation and the versions a result depends on"),
}


# ---------------------------------------------------------------- headless Chromium (report and site tests)

def chrome():
    """Headless Chromium at 1280 x 900 through Selenium (Debian's chromium and chromium-driver); skips,
    saying why, where either is missing or the browser cannot start."""
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


def all_images_loaded(drv) -> list:
    """The page's images made eager and awaited; returns the sources of those that did not load."""
    drv.execute_script("document.querySelectorAll('details').forEach(d => d.open = true);"
                       "document.querySelectorAll('img[loading=lazy]').forEach(i => i.loading = 'eager')")
    return drv.execute_async_script(
        "const done = arguments[0]; const imgs = Array.from(document.querySelectorAll('img'))"
        ".filter(i => i.getAttribute('src'));"
        "Promise.all(imgs.map(i => i.decode().catch(() => null))).then(() =>"
        " done(imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute('src'))))")
