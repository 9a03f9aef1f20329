"""Regenerate docs/gallery/ from the default experiment and experiments/engine_defaults.toml:
the default run's summary (table.md's first sections) in docs/results/default.md, the engine
defaults against the best possible, error images and a screenshot of the default run's report.html.

    .venv/bin/python scripts/gallery.py [results folder of a default run] [--default-only]

A folder holding a complete default run is read as it is; otherwise the default experiment
runs into it (or into a temporary folder).
"""
import json
import shutil
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import dsm
from dsm.report import figures, io as report, summary
from dsm.cli import DEFAULT_CONFIG
from dsm.truth.metrics import CLASS_COLORS, CLASS_NAMES

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "gallery"
RESULTS_PAGE = ROOT / "docs" / "results" / "default.md"


def default_run(folder):
    """A complete default run's folder: the one given if it holds one, else a fresh run."""
    if folder is not None and (Path(folder) / "run.json").is_file():
        run = json.loads((Path(folder) / "run.json").read_text())
        if run.get("state") == "complete" and run.get("experiment") == "default":
            return Path(folder)
    # an unfinished or foreign run in the folder is replaced (dsm.run keeps it unless told)
    return dsm.run(DEFAULT_CONFIG, out=folder, force=folder is not None and (Path(folder) / "run.json").is_file()).out


def screenshot(page: Path, png: Path, size=(1280, 900)) -> bool:
    """report.html's first screen in headless Chromium (Selenium); False where it cannot run here."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        return False
    browser, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if not browser or not driver:
        return False
    opts = Options()
    opts.binary_location = browser
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", f"--window-size={size[0]},{size[1]}"):
        opts.add_argument(a)
    drv = webdriver.Chrome(service=Service(driver), options=opts)
    try:
        drv.get(page.resolve().as_uri())
        return drv.save_screenshot(str(png))
    finally:
        drv.quit()


def results_table(table: str, run: dict):
    """docs/results/default.md's table, between its two markers: the summary's sections as written,
    after a line naming the run's commit, machine and variant."""
    page = RESULTS_PAGE
    text = page.read_text()
    a, b = "<!-- default-table: scripts/gallery.py writes from here -->\n", "<!-- default-table: to here -->\n"
    if a not in text or b not in text:
        print(f"{page}: the default-table markers are missing; table left as it is", file=sys.stderr)
        return
    body = [line for line in table.splitlines() if line.strip() != "## Summary"]
    head, rest = text.split(a, 1)
    page.write_text(head + a + provenance(run) + "\n\n" + "\n".join(body).strip("\n") + "\n" + b
                    + rest.split(b, 1)[1])


def provenance(run: dict) -> str:
    """Which commit, machine and variant a run's numbers come from (its run.json)."""
    from dsm.benchmark.results import machine
    m = machine()
    commit = run.get("versions", {}).get("dsm_git_commit", "unknown")
    return (f"*From a default run at commit `{commit}`, variant {run.get('variant', 'llvm_ad_rgb')}, on "
            f"{m['cpu']} ({m['cores']} cores), written by `scripts/gallery.py`.*")


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    out = default_run(args[0] if args else None)
    OUT.mkdir(parents=True, exist_ok=True)
    rows = report.read_rows(out / "metrics.csv")
    # the results page's table: table.md's summary sections, as the run wrote them
    (OUT / "default_table.md").write_text("\n".join(summary.summary_md(rows)) + "\n")
    results_table((OUT / "default_table.md").read_text(), json.loads((out / "run.json").read_text()))
    # the images: the room's own point light, cube view, R = 512, four schemes
    from PIL import Image
    pick = [("none", ""), ("constant", "bias=2 texel"), ("normal_offset", "offset=1.5 texel bias=0"), ("adaptive", "K=0.0001")]
    fig = Figure(figsize=(13, 3.9))
    axes = fig.subplots(1, len(pick))
    for ax, (scheme, params) in zip(axes, pick):
        r = next(r for r in rows if (r["scene"], r["light"], r["view"], r["resolution"], r["scheme"], r["params"]) ==
                 ("room", "0:point", "cube", 512, scheme, params))
        ax.imshow(np.asarray(Image.open(out / figures.image_paths(r)[0]).convert("RGB")))
        ax.set_title(f"{scheme} {params}\nacne {r['acne_rate']:.3f}, peter-panning {r['peterpan_rate']:.3f}", fontsize=9)
        ax.axis("off")
    from matplotlib.patches import Patch
    fig.legend(handles=[Patch(color=c / 255, label=n) for c, n in zip(CLASS_COLORS, CLASS_NAMES)], loc="lower center",
               ncol=5, fontsize=9, frameon=False)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.86, bottom=0.09, wspace=0.04)
    fig.savefig(OUT / "room_point_cube_errors.png", dpi=80)
    if not screenshot(out / "report.html", OUT / "report_html.png"):
        print("no screenshot of report.html: selenium or chromium is missing", file=sys.stderr)
    run = json.loads((out / "run.json").read_text())
    print(f"{run['n_empty']} empty cases, {run['n_failed']} failed; measuring {run['timing']['measure_s']:.1f} s, "
          f"report {run['timing']['report_s']:.1f} s")
    print((OUT / "default_table.md").read_text())


def engine_defaults():
    """Every engine preset on the default experiment's cases beside the exact oracles of the
    same maps: objective E = (acne + peter-panning) / receivers (lambda 1, nearest)."""
    res = dsm.run(ROOT / "experiments" / "engine_defaults.toml")
    maps = {}
    for o in res.oracle:
        if o["lambda"] == 1.0 and o["format"] == "float32":
            maps[(o["scene"], o["light"], o["view"], o["resolution"], o["culling"])] = o
    key = lambda r: (r["scene"], r["light"], r["view"], r["resolution"], r["culling"])
    groups = defaultdict(list)
    for r in res.rows:
        if r["n_receivers"] and key(r) in maps:
            groups[r["preset"] or f"{r['scheme']} {r['params']}"].append(r)
    oracle_rows = list(maps.values())
    mean = lambda xs: float(np.nanmean(np.array(xs, float))) if xs else float("nan")
    lines = ["| scheme or oracle | cases | objective E, mean | median | acne rate, mean | peter-panning rate, mean | "
             "E above the world oracle, mean | cases at or below the world oracle |", "|---|---|---|---|---|---|---|---|"]
    for tag, name in (("per_texel", "oracle: best bias per texel (the resolution's share)"),
                      ("world", "oracle: best constant world bias per map"),
                      ("texel", "oracle: best constant texel bias per map")):
        e = [o[f"{tag}_objective"] for o in oracle_rows]
        lines.append(f"| {name} | {len(e)} | {mean(e):.4f} | {np.nanmedian(e):.4f} | "
                     f"{mean([o[f'{tag}_acne_rate'] for o in oracle_rows]):.4f} | "
                     f"{mean([o[f'{tag}_peterpan_rate'] for o in oracle_rows]):.4f} | | |")
    for name, rs in sorted(groups.items(), key=lambda kv: mean([r["error_rate"] for r in kv[1]])):
        e = [r["error_rate"] for r in rs]
        w = [maps[key(r)]["world_objective"] for r in rs]
        below = sum(1 for a, b in zip(e, w) if a <= b)
        lines.append(f"| {name} | {len(rs)} | {mean(e):.4f} | {np.nanmedian(e):.4f} | "
                     f"{mean([r['acne_rate'] for r in rs]):.4f} | {mean([r['peterpan_rate'] for r in rs]):.4f} | "
                     f"{mean([a - b for a, b in zip(e, w)]):+.4f} | {below} |")
    (OUT / "engine_defaults_table.md").write_text("\n".join(lines) + "\n")
    print((OUT / "engine_defaults_table.md").read_text())


if __name__ == "__main__":
    main()
    if "--default-only" not in sys.argv:
        engine_defaults()
