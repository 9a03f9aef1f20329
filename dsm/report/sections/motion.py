"""A motion run's files: frames.csv (one row per case and frame) and the flicker plots drawn from it."""
from __future__ import annotations

from .. import figures, glyph_cache, io as report
from ...truth import metrics

FRAME_COLUMNS = ("case", "motion", "scene", "light", "cascade_layout", "scheme", "params", "resolution", "filter",
                 "format", "frame", "map_built", "n_points_visible", "n_pairs_eligible", "n_flicker", "flicker_rate",
                 "n_eligible_within", "flicker_within_rate", "n_eligible_change", "flicker_change_rate",
                 "flicker_magnitude", "n_receivers", "acne_rate", "peterpan_rate", "error_rate", "cache", "n_ghost",
                 "ghost_rate", "n_missing", "missing_rate", "recast_fraction", "frame_build_ms")


def write_frames_csv(path, rows):
    """frames.csv: one row per case and frame (the flicker of the pair ending at that frame)."""
    report.write_csv(path, FRAME_COLUMNS, rows)


def flicker_curves(frame_rows) -> list:
    """(case meta, [(frame, flicker rate of the pair ending there)]) per case, from frames.csv's
    rows as text (an empty cell: undefined)."""
    out, index = [], {}
    for r in frame_rows:
        if r["case"] not in index:
            index[r["case"]] = len(out)
            out.append((r, []))
        if int(r["frame"]) > 0:
            rate = float(r["flicker_rate"]) if r["flicker_rate"] != "" else metrics.UNDEFINED
            out[index[r["case"]]][1].append((int(r["frame"]), rate))
    return out


def write_plots(folder, frame_rows):
    """plots/flicker_<scene>_<light>_<motion>.png: flicker rate against frame, one line per case
    (from frames.csv's rows: dsm.report.publish composes it, for a run and a rebuild)."""
    curves = flicker_curves(frame_rows)
    if not curves:
        return
    from matplotlib.figure import Figure
    folder.mkdir(exist_ok=True)
    groups = {}
    for meta, c in curves:
        groups.setdefault((meta["scene"], meta["light"], meta["motion"]), []).append((meta, c))
    for (scene, light, path_label), items in groups.items():
        fig = Figure(figsize=(10, 4))
        glyph_cache.canvas(fig)           # matplotlib's text drawing, its work kept across figures
        ax = fig.subplots()
        for meta, c in items:
            pts = [(x, y) for x, y in c if metrics.defined(y)]
            ax.plot([p[0] for p in pts], [p[1] for p in pts], ".-", lw=0.8,
                    label=f"{meta['cascade_layout']} {meta['scheme']} {meta['params']} {meta['filter']}".strip())
        ax.set_xlabel("frame (flicker between it and the one before)")
        ax.set_ylabel("flicker rate (fixed points)")
        ax.set_title(f"{scene}, light {light}: {path_label}", fontsize=9)
        fig.subplots_adjust(left=0.08, right=0.6, bottom=0.13, top=0.9)
        ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=5, frameon=False)
        with report.atomic(folder / f"flicker_{figures.slug(f'{scene}_{light}_{path_label}', keep='-_')}.png") as tmp:
            fig.savefig(tmp, dpi=80, format="png")
