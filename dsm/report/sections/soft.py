"""Area lights in the report: V, V* and |V - V*| images per case and the MAE-by-region plots.

Drawn after the timed work like every other image and figure (:mod:`dsm.report.publish`): the runner
keeps each area-light case's small arrays (:func:`image_item`) and hands them over at the end.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import figures, glyph_cache, png, tables as report, io as report_io

IMAGES = (("v", "viridis"), ("vstar", "viridis"), ("abserr", "magma"))


def image_item(row: dict, width: int, height: int, pixels, v, v_star):
    """What :func:`write_images` needs for one area-light case (paths relative to the run)."""
    base = f"images/{figures.image_folder(row)}/{row['case']}"
    return base, int(width), int(height), np.asarray(pixels), np.asarray(v, np.float32), \
        np.asarray(v_star, np.float32)


def write_images(out: Path, items: list):
    """``<case>_v.png``, ``_vstar.png`` (viridis), ``_abserr.png`` (magma): black outside the receivers."""
    from matplotlib import colormaps
    for base, w, h, pixels, v, v_star in items:
        for name, cmap in IMAGES:
            values = {"v": v, "vstar": v_star, "abserr": np.abs(v - v_star)}[name]
            rgb = np.zeros((w * h, 3), np.uint8)
            rgb[pixels] = np.round(colormaps[cmap](np.clip(values, 0, 1))[:, :3] * 255).astype(np.uint8)
            p = Path(out) / f"{base}_{name}.png"
            p.parent.mkdir(parents=True, exist_ok=True)
            png.write(p, rgb.reshape(h, w, 3))


def plot_jobs(folder: Path, rows: list) -> list:
    """(function, args) jobs drawing ``soft_<scene>_<light>.png`` per area light: MAE of V
    against V* by region, one bar per scheme and filter (no bar: an empty region)."""
    groups = {}
    for r in report.soft_rows(rows):
        groups.setdefault((r["scene"], r["light"]), []).append(
            (f"{r['scheme']} {r['filter']}", r["filter"], r["mae_umbra"], r["mae_penumbra"], r["mae_lit"]))
    return [(draw, (Path(folder) / f"soft_{figures.slug(f'{s}_{l}')}.png", f"{s}, light {l}", bars))
            for (s, l), bars in sorted(groups.items())]


def draw(path: Path, title: str, bars: list):
    """Draw into ``path`` the MAE of V against V* per region (umbra, penumbra, lit), a bar per entry of ``bars``."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8.5, 3.6))
    glyph_cache.canvas(fig)           # matplotlib's text drawing, its work kept across figures
    axes = fig.subplots(1, 3, sharey=True)
    filters = sorted({b[1] for b in bars})
    for k, (ax, region) in enumerate(zip(axes, ("umbra", "penumbra", "lit"))):
        ax.bar(range(len(bars)), [float(b[2 + k]) for b in bars],      # NaN (an empty region): no bar
               color=[f"C{filters.index(b[1]) % 10}" for b in bars])
        ax.set_xticks(range(len(bars)), [b[0] for b in bars], rotation=90, fontsize=6)
        ax.set_title(f"MAE {region}", fontsize=8)
    fig.suptitle(f"{title}: |V - V*| by region", fontsize=8)
    fig.subplots_adjust(bottom=0.42, top=0.86, left=0.07, right=0.99)
    report_io.save_png(Path(path), lambda f, fmt: fig.savefig(f, dpi=80, format=fmt))


