"""A cascaded run's files: cascades.csv and cascades.md (per case and cascade), cascade_curves.csv,
the cascade index images and plots/cascades_*.png (error and texels per pixel against distance)."""
from __future__ import annotations

import csv

import numpy as np

from .. import figures, glyph_cache, io as report
from ...truth import metrics


CSV_COLUMNS = ("case", "scene", "light", "cascade_layout", "scheme", "params", "resolution", "filter", "format",
               "cascade", "split_near", "split_far", "extent", "texel_size", "near", "far", "n_receivers", "n_acne",
               "n_peterpan", "acne_rate", "peterpan_rate", "error_rate", "texels_per_pixel_median")


def write_csv(path, rows: list):
    """cascades.csv: one row per case and cascade (undefined values: empty cells)."""
    report.write_csv(path, CSV_COLUMNS, rows)


def write_table(path, rows: list):
    """cascades.md from cascades.csv's rows (dsm.report.publish composes it, for a run and a rebuild)."""
    lines = ["# Cascades", "", "Per case and cascade (cascades.csv): its range of camera view depth, texel size, "
             "receivers, error rates and the median shadow-map texels per camera pixel (below 1: perspective "
             "aliasing). Undefined values: -.", "",
             "| case | scene | layout | scheme | params | R | filter | format | cascade | view depth | texel | "
             "receivers | acne | peter-pan | error | texels/pixel |", "|---" * 16 + "|"]
    cell = lambda x: ("-" if not metrics.defined(x) else f"{x:.4g}") if isinstance(x, float) else str(x)
    for r in rows:
        lines.append("| " + " | ".join(cell(r.get(k, "")) for k in (
            "case", "scene", "cascade_layout", "scheme", "params", "resolution", "filter", "format", "cascade"))
            + f" | {r['split_near']:.3g} to {r['split_far']:.3g} | " + " | ".join(cell(r[k]) for k in (
                "texel_size", "n_receivers", "acne_rate", "peterpan_rate", "error_rate", "texels_per_pixel_median"))
            + " |")
    with report.atomic(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


CURVE_META = ("case", "scene", "light", "cascade_layout", "scheme", "params", "resolution", "filter", "format")
CURVE_COLUMNS = CURVE_META + ("distance", "error_rate", "texels_per_pixel")


def write_curves_csv(path, curves: list):
    """cascade_curves.csv: each case's error rate and texels per pixel against camera distance (the
    points of plots/cascades_*.png), floats written exactly (repr) so a rebuild draws the same."""
    with report.atomic(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CURVE_COLUMNS)
        for meta, curve in curves:
            for point in curve:
                w.writerow([meta.get(k, "") for k in CURVE_META] + [repr(float(x)) for x in point])


def read_curves_csv(path) -> list:
    """(case meta, [(distance, error rate, texels per pixel)]) per case, in the file's order."""
    out, index = [], {}
    for r in report.read_csv(path):
        if r["case"] not in index:
            index[r["case"]] = len(out)
            out.append(({k: r[k] for k in CURVE_META}, []))
        out[index[r["case"]]][1].append(tuple(float(r[k]) for k in ("distance", "error_rate", "texels_per_pixel")))
    return out


CASCADE_COLORS = np.array([[0, 0, 0], [228, 26, 28], [55, 126, 184], [77, 175, 74], [152, 78, 163],
                           [255, 127, 0], [255, 255, 51], [166, 86, 40], [247, 129, 191]], np.uint8)


def write_index_image(path, pixels: np.ndarray, face: np.ndarray, width: int, height: int):
    """images/<scene>_<light>/<case>_cascade.png: each receiver coloured by its cascade (black: not a receiver)."""
    from matplotlib.image import imsave
    img = np.zeros(width * height, np.uint8)
    img[pixels] = np.asarray(face, int) + 1
    with report.atomic(path) as tmp:
        imsave(tmp, CASCADE_COLORS[img.reshape(height, width)], format="png")


def write_plots(folder, curves: list):
    """plots/cascades_<scene>_<light>.png: error rate and texels per pixel against distance from the
    camera, one line per cascade layout, resolution, scheme, filter and format."""
    if not curves:
        return
    from matplotlib.figure import Figure
    folder.mkdir(exist_ok=True)
    groups = {}
    for meta, curve in curves:
        if curve:
            groups.setdefault((meta["scene"], meta["light"]), []).append((meta, curve))
    for (scene, light), items in groups.items():
        fig = Figure(figsize=(11, 4))
        glyph_cache.canvas(fig)           # matplotlib's text drawing, its work kept across figures
        a1, a2 = fig.subplots(1, 2)
        for meta, curve in items:
            x = [c[0] for c in curve]
            lab = f"{meta['cascade_layout']} R={meta['resolution']} {meta['scheme']} {meta['params']}".strip()
            a1.plot(x, [c[1] for c in curve], ".-", lw=0.8, label=lab)
            a2.plot(x, [c[2] for c in curve], ".-", lw=0.8, label=lab)
        for ax, what in ((a1, "error rate"), (a2, "texels per camera pixel (median)")):
            ax.set_xscale("log")
            ax.set_xlabel("distance from the camera")
            ax.set_ylabel(what)
        a2.set_yscale("log")
        a2.axhline(1.0, color="k", lw=0.5)
        fig.suptitle(f"{scene}, light {light}: cascades against distance", fontsize=9)
        fig.subplots_adjust(left=0.06, right=0.66, bottom=0.13, top=0.9, wspace=0.3)
        h, l = a1.get_legend_handles_labels()
        fig.legend(h, l, loc="center left", bbox_to_anchor=(0.67, 0.5), fontsize=5, frameon=False)
        with report.atomic(folder / f"cascades_{figures.slug(f'{scene}_{light}', keep='-_')}.png") as tmp:
            fig.savefig(tmp, dpi=80, format="png")
