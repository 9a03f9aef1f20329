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
    v = env.use_variant(os.environ.get("DSM_VARIANT"))
    yield v
    import drjit as dr
    dr.sync_thread()
    dr.flush_kernel_cache()
    dr.flush_malloc_cache()


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

    def _run(cfg, name="out"):
        return dsm.run(cfg, out=tmp_path / name)
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
