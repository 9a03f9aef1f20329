"""A run with moving casters (``[[motion]] casters``, ``cache``): cache.md and report.html's section (per motion
case: its policy, ghost and missing rates, their worst frame, the fraction re-cast and the maps cast), the
plot of the error the cache leaves against the update budget it spends per policy
(plots/cache_budget_<scene>_<light>[_<layout>].png), and each case's frames as an animated GIF of its classes with the
ghosts and missing shadows in their own colours (images/<scene>_<light>/<case>_cache.gif)."""
from __future__ import annotations

import numpy as np

from .. import figures, glyph_cache, io as report
from ..templates import Cell, Row, Table, render
from . import md
from ...truth import metrics

COLUMNS = (("case", "case"), ("scene", "scene"), ("light", "light"), ("motion", "path"), ("cache", "cache"),
           ("cascade_layout", "layout"), ("scheme", "scheme"), ("params", "params"), ("ghost_rate", "ghost"),
           ("ghost_rate_worst", "worst ghost"), ("missing_rate", "missing"), ("missing_rate_worst", "worst missing"),
           ("recast_fraction", "re-cast"), ("maps_built", "maps cast"))
INTRO = ("Per motion case (metrics.csv): its cache policy, the ghost rate (receivers the cached map shadows where "
         "this frame's map leaves them lit, over those it leaves lit) and the missing rate (the converse, over "
         "those it shadows), each the mean over the frames and the worst frame, the fraction of the map's texels "
         "(a virtual map's: pages) re-cast per frame and the whole maps cast. Each case's frames: "
         "images/<scene>_<light>/<case>_cache.gif (ghosts and missing shadows in their own colours). "
         "Undefined: -.")
GHOST, MISSING = 1, 2                      # a frame's cache image: 0 neither, 1 a ghost, 2 a missing shadow
GHOST_COLOR, MISSING_COLOR = (0, 220, 120), (255, 140, 0)
DIM = 0.45                                 # the classes under the ghosts: their colours' grey at this brightness
FRAME_MS = 250
PLOT_PREFIX = "cache_budget_"
POLICY_STYLE = {"none": ("k", "o"), "static": ("tab:red", "s"), "stagger": ("tab:blue", "^"),
                "invalidate": ("tab:green", "D")}


def cache_rows(rows: list) -> list:
    """The motion cases that name a cache policy (metrics.csv's rows)."""
    return [r for r in rows if r.get("motion") and r.get("cache")]


def write_table(path, rows: list) -> bool:
    """cache.md from metrics.csv's rows; False (nothing written, a stale one removed) without a motion case."""
    rows = cache_rows(rows)
    if not rows:
        if path.is_file():
            path.unlink()
        return False
    md.write_table(path, "Moving casters and cached maps", INTRO, COLUMNS, rows)
    return True


def html_table(rows: list, out=None) -> dict | None:
    """report.html's section on the run's cached maps: its words and table, each case's cache GIF linked where
    the run folder ``out`` holds it (None without a motion case)."""
    rows = cache_rows(rows)
    if not rows:
        return None
    def gif(r):
        path = gif_path(figures.frames_path(r))
        return Cell("GIF", href=path) if out is not None and (out / path).is_file() else Cell("-")
    body = [Row([Cell(md.cell(r.get(k, ""))) for k, _ in COLUMNS] + [gif(r)]) for r in rows]
    return {"intro": INTRO, "table": Table([(h, None) for _, h in COLUMNS] + [("frames", None)], body, box="wide")}


def html_section(rows: list, out=None) -> str:
    """report.html's section on the run's cached maps, alone ("" without one)."""
    return render("cache.html", cache=html_table(rows, out))


def budget_points(rows: list) -> dict:
    """{(scene, light, layout): [(policy, re-cast fraction, ghost + missing rate, path label)]}: the cases whose
    rates are both defined (``stagger:N`` keeps its N; layout: the cascade layout, empty on a single map)."""
    out = {}
    for r in cache_rows(rows):
        g, m, f = r.get("ghost_rate"), r.get("missing_rate"), r.get("recast_fraction")
        if all(isinstance(x, (int, float)) and metrics.defined(x) for x in (g, m, f)):
            key = (r["scene"], r["light"], str(r.get("cascade_layout") or ""))
            out.setdefault(key, []).append((str(r["cache"]), float(f), float(g) + float(m), str(r["motion"])))
    return out


def write_plots(folder, rows: list):
    """plots/cache_budget_<scene>_<light>[_<layout>].png: per motion case, the ghost + missing rate (means over its
    frames) against the fraction of the map re-cast per frame, a colour and marker per policy; a path whose label
    is not its policy's name is named beside its point (coincident points in one label)."""
    groups = budget_points(rows)
    if not groups:
        return
    from matplotlib.figure import Figure
    folder.mkdir(exist_ok=True)
    for (scene, light, layout), pts in sorted(groups.items()):
        fig = Figure(figsize=(6, 4))
        glyph_cache.canvas(fig)           # matplotlib's text drawing, its work kept across figures
        ax = fig.subplots()
        for policy in sorted({p[0] for p in pts}):
            mine = [p for p in pts if p[0] == policy]
            colour, marker = POLICY_STYLE.get(policy.partition(":")[0], ("grey", "x"))
            ax.plot([p[1] for p in mine], [p[2] for p in mine], marker, color=colour, ls="none", label=policy)
        named = {}
        for policy, x, y, label in pts:
            if label != policy:
                named.setdefault((x, y), []).append(label)
        for (x, y), labels in sorted(named.items()):
            ax.annotate("; ".join(labels), (x, y), xytext=(5, -9), textcoords="offset points", fontsize=6)
        ax.set_xlabel("update budget: fraction of the map re-cast per frame (mean)")
        ax.set_ylabel("ghost + missing rate (mean over frames)")
        ax.set_xlim(-0.05, 1.1)
        where = f"{scene}, light {light}" + (f", {layout}" if layout else "")
        ax.set_title(f"{where}: the cache's error against what it casts", fontsize=9)
        ax.legend(fontsize=7, frameon=False)
        fig.subplots_adjust(left=0.13, right=0.97, bottom=0.13, top=0.9)
        stem = figures.slug("_".join(x for x in (scene, light, layout) if x), keep="-_")
        with report.atomic(folder / f"{PLOT_PREFIX}{stem}.png") as tmp:
            fig.savefig(tmp, dpi=80, format="png", metadata={"Software": None})


def gif_path(frames_gif: str) -> str:
    """A case's cache GIF beside its frames GIF (dsm.report.figures.frames_path): <case>_cache.gif."""
    return frames_gif[: -len("_frames.gif")] + "_cache.gif"


def palette() -> np.ndarray:
    """(10, 3) uint8: the classes' colours dimmed to grey (index = class), then the ghost's and the missing's."""
    grey = np.round(DIM * metrics.CLASS_COLORS.astype(float) @ [0.299, 0.587, 0.114]).astype(np.uint8)
    return np.concatenate([np.repeat(grey[:, None], 3, 1), [GHOST_COLOR, MISSING_COLOR]]).astype(np.uint8)


def frame_indices(classes: np.ndarray, cache: np.ndarray) -> np.ndarray:
    """A GIF frame as palette indices: the class image, ghosts and missing shadows over it."""
    n = len(metrics.CLASS_COLORS)
    out = np.asarray(classes, np.uint8).copy()
    out[cache == GHOST] = n
    out[cache == MISSING] = n + 1
    return out


def write_gif(path, classes: list, cache: list):
    """The frames' classes with the ghosts and missing shadows in their own colours as an animated GIF (Pillow,
    one fixed palette, no optimisation: the same frames give the same bytes)."""
    from PIL import Image
    pal = palette().tobytes()
    images = []
    for c, k in zip(classes, cache):
        im = Image.fromarray(frame_indices(c, k), "P")
        im.putpalette(pal)
        images.append(im)
    path.parent.mkdir(parents=True, exist_ok=True)
    with report.atomic(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=FRAME_MS, loop=0,
                       optimize=False)
