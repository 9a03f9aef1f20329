"""The report's figures and case images, drawn after the measurements (by worker processes when
there is enough to draw), so drawing never overlaps a timed build or lookup.

Every rate axis is symlog (linear below 1e-4, so a zero and 1e-4 are both visible) from 0 to 1;
a rate-against-parameter figure has a column of panels per parameter unit (texel, world,
range, K, ...); time axes are log; every figure names its scene, light, view and resolution;
no panel's legend has more than MAX_LEGEND (13) entries (more series are spread over more panels).
Figures are drawn with matplotlib's Agg canvas (no pyplot: a notebook's backend stays as it is;
dsm/report/canvas.py: texts as cached whole-string bitmaps, one Figure per layout while
jobs.run_jobs draws); figures and case images are written by dsm/report/png.py (zlib level 1, no row
filters: a third of Pillow's time for files of the same size).
"""
from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import numpy as np

from ..truth import metrics
from . import canvas, frontier
from . import png
from ..core.labels import params_label
from .io import atomic

LINTHRESH = 1e-4          # symlog: linear below this rate
MAX_LEGEND = 13           # entries per panel (more make more panels, the costliest artists)
# drawn at 120 dpi and shown at its pixel size (report.html: one image pixel a CSS pixel, 96 a CSS
# inch), a figure reads at 1.25 times its size in points: its smallest text, 7.2 points, reads as 9.
# (Any DPI x MIN_FONT of 864 reads at 9; 120 and 7.2 draw 2.8 times the pixels of the earlier 72 dpi
# figures, where 144 and 6 drew 4 times: text a fifth larger beside the same panels, a third less
# of the report's drawing and PNG time.)
DPI = 120
MIN_FONT = 7.2            # points: no text of a figure is smaller (9 points as shown)
LABEL_FONT = 7.5          # axis labels and panel titles
TITLE_FONT = 8.5          # a figure's title
PNG = {"compress_level": 1}
# the figures' settings, while making and drawing them: MIN_FONT tick labels (set once, not per
# panel: tick_params re-styles every tick already made); glyphs unhinted (FreeType's autohinter
# is a tenth of the drawing time and sharpens little at these sizes)
RC = {"xtick.labelsize": MIN_FONT, "ytick.labelsize": MIN_FONT, "text.hinting": "no_hinting"}
# series styles: Okabe & Ito's colour-blind-safe palette (Color Universal Design, 2008) without its
# yellow (too faint on white) and black (the frontier's and the oracle's lines), times four marker
# and dash pairs: 24 series that differ in colour and in shape, so none is told by colour alone
COLOURS = ("#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7")
MARKERS = ("o", "s", "^", "D")
DASHES = ("-", "--", ":", "-.")
N_STYLES = len(COLOURS) * len(MARKERS)
CYCLE = COLOURS           # colour k of a series is CYCLE[k % len(CYCLE)] (style(k) adds its marker and dash)


def style(k: int) -> dict:
    """Series k's colour, marker and dash: distinct for k < N_STYLES (colour first, then the shape)."""
    k %= N_STYLES
    j = k // len(COLOURS)
    return {"color": COLOURS[k % len(COLOURS)], "marker": MARKERS[j], "ls": DASHES[j]}


def slug(s: str, keep: str = "-_.") -> str:
    """``s`` as a file name: every character but letters, digits and ``keep`` made ``_``."""
    return _slug(str(s), keep)


@functools.lru_cache(maxsize=4096)
def _slug(s: str, keep: str) -> str:
    # a report names a case's image folder (its scene and light) for every case: a few strings, many times
    return "".join(c if c.isalnum() or c in keep else "_" for c in s)


def image_folder(row) -> str:
    """images/<this>/: one sub-folder per scene and light."""
    return slug(f"{row['scene']}_{row['light']}")


# the files a case writes under images/<scene>_<light>/: <case>_<kind> (error and shadow here,
# cascade in dsm.maps.cascades, level in dsm.report.sections.virtual, frames in dsm.experiment.motion, v, vstar and abserr in dsm.report.sections.soft)
CASE_IMAGE_KINDS = ("error.png", "shadow.png", "cascade.png", "frames.gif", "v.png", "vstar.png", "abserr.png",
                    "contact.png", "level.png")


def image_paths(row) -> tuple:
    """(error image, shadow image) of a case, relative to the run's folder."""
    f = f"images/{image_folder(row)}/{row['case']}"
    return f + "_error.png", f + "_shadow.png"


CLASSES_GIF_COMMENT = b"dsm: the frames' class images"   # in a motion GIF of class images, not display renders


def frames_path(row) -> str:
    """A motion case's animated GIF (dsm.experiment.motion_display), relative to the run's folder."""
    return f"images/{image_folder(row)}/{row['case']}_frames.gif"


# a scene and light's display renders (dsm.experiment.display), one pair per images/<scene>_<light>/
DISPLAY_FILES = ("display_nl.png", "display_exact.png")


def display_paths(row) -> tuple:
    """(N.L display render, exact display render) of a case's scene and light, relative to the run's folder."""
    return tuple(f"images/{image_folder(row)}/{name}" for name in DISPLAY_FILES)


def _atomic_save(path: Path, save):
    with atomic(path) as tmp:
        save(tmp)


# ------------------------------------------------------------------ case images

def shade_image(shade: np.ndarray) -> np.ndarray:
    """A shadow-mapped render in [0, 1] as 8-bit grey (what the PNG stores)."""
    return np.round(np.clip(shade, 0, 1) * 255).astype(np.uint8)


def write_images(out: Path, items: list):
    """items: (error path, class image (H, W) uint8 or None, shadow path, 8-bit grey image or None)."""
    for err_path, classes, shadow_path, grey in items:
        for path, img in ((err_path, classes), (shadow_path, grey)):
            if img is None:
                continue
            p = Path(out) / path
            pixels = metrics.CLASS_COLORS[img] if img is classes else img     # RGB, as readers of a PNG expect
            try:
                png.write(p, pixels)
            except FileNotFoundError:           # its folder (one per scene and light) made on first use
                p.parent.mkdir(parents=True, exist_ok=True)
                png.write(p, pixels)


# ------------------------------------------------------------------ drawing primitives

# where a legend's first entry sits: this far below its panel, in inches (clear of the tick labels
# and the x label), whatever the panel's height: a fraction of the height put a tall panel's legend
# below the room _figure leaves for it, its last lines cut off
LEGEND_GAP_IN = 0.45


def _figure(ncols, nrows, width=3.7, height=2.5, legend_rows=0, sharey=False, sharex=False):
    """A figure of nrows x ncols panels, room below them for ``legend_rows`` legend entries;
    shared axes hide the inner panels' tick labels (fewer texts to lay out and draw)."""
    from matplotlib import rc_context
    from matplotlib.figure import Figure
    extra = 0.2 * legend_rows + 0.75

    def make():
        fig = Figure(figsize=(width * ncols + 0.3, height * nrows + extra))
        with rc_context(RC):
            return fig, np.array(fig.subplots(nrows, ncols, squeeze=False, sharey="row" if sharey else False,
                                              sharex="col" if sharex else False))
    # one Figure per layout while jobs.run_jobs draws (canvas.reusing): the legend's rows only resize it
    fig, axes = canvas.pooled((ncols, nrows, width, height, sharey, sharex), make, scales=False)
    fig.set_size_inches(width * ncols + 0.3, height * nrows + extra)
    fig.subplots_adjust(left=0.55 / (width * ncols + 0.3), right=0.98, top=1 - 0.6 / (height * nrows + extra),
                        bottom=(0.2 * legend_rows + 0.5) / (height * nrows + extra), wspace=0.32, hspace=0.42)
    return fig, axes


SCALE_DEFAULTS = {"linear": {}, "log": {"base": 10}, "symlog": {"base": 10, "linscale": 1}}


def set_scale(ax, which: str, name: str, **params):
    """``ax.set_xscale`` (which "x") or ``set_yscale`` (name, params), unless the axis has that
    scale with those parameters already (a pooled figure's panel: a scale set anew is a new
    Scale object and its axis reset, a tenth of a pooled figure's cost). Every axis of
    ``_figure``'s panels is set by this (canvas.pooled leaves the last figure's scales)."""
    axis = ax.xaxis if which == "x" else ax.yaxis
    want = {**SCALE_DEFAULTS[name], **params}
    t = axis.get_transform()
    if axis.get_scale() == name and all(getattr(t, k, None) == v for k, v in want.items()):
        return
    (ax.set_xscale if which == "x" else ax.set_yscale)(name, **params)


RATE_TICKS = (0, 1e-4, 1e-3, 1e-2, 1e-1, 1)
RATE_LABELS = ("0", "1e-4", "0.001", "0.01", "0.1", "1")


RATE_LABEL_PAD = (26, 15)  # points between a rate axis (y, x) and its label: room for its tick labels


def _rate_axis(ax, which="y"):
    """A rate axis: symlog from 0 to 1 with fixed plain tick labels, drawn as one line of tick
    marks and a text per label (on the outer panels only) rather than matplotlib's ticks, five
    artists each and two fifths of a figure's drawing time."""
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullLocator
    from matplotlib.transforms import blended_transform_factory
    y = which == "y"
    set_scale(ax, which, "symlog", linthresh=LINTHRESH, linscale=0.6)
    (ax.set_ylim if y else ax.set_xlim)(0, 1)
    axis = ax.yaxis if y else ax.xaxis
    axis.set_major_locator(NullLocator())
    axis.set_minor_locator(NullLocator())
    at = blended_transform_factory(ax.transAxes, ax.transData) if y else \
        blended_transform_factory(ax.transData, ax.transAxes)
    zeros = [0.0] * len(RATE_TICKS)
    ax.add_artist(Line2D(zeros if y else RATE_TICKS, RATE_TICKS if y else zeros, transform=at, ls="none",
                         marker=2 + (not y), ms=3.5, mew=0.8, color="k", clip_on=False))    # TICKLEFT, TICKDOWN
    spec = ax.get_subplotspec()
    if spec is None or (spec.is_first_col() if y else spec.is_last_row()):
        xy = [(-0.025, v) if y else (v, -0.04) for v in RATE_TICKS]
        ax.add_artist(canvas.tick_labels(xy, RATE_LABELS, at, "right" if y else "center", "center" if y else "top",
                                         RC["ytick.labelsize"]))
    axis.labelpad = RATE_LABEL_PAD[0 if y else 1]


def _x_scale(ax, xs, log2=False, log=False):
    """Linear, or log where the positive values span more than a factor 50 (symlog if a 0 is among
    them); a single value gets a single tick. Few ticks, no minor ones, plain labels."""
    from matplotlib.ticker import (FixedLocator, FuncFormatter, LogLocator, MaxNLocator, NullLocator)
    xs = np.array([x for x in xs if math.isfinite(x)], float)
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    axis = ax.xaxis
    if log2:
        set_scale(ax, "x", "log", base=2)
        values = sorted(set(xs.tolist()))
        if len(values) <= 4 and all(v == 2 ** round(math.log2(v)) for v in values if v > 0):
            axis.set_major_locator(FixedLocator(values))     # resolutions: each one labelled
        else:                                                # texel counts: powers of two
            axis.set_major_locator(LogLocator(base=2, numticks=6))
            plain = FuncFormatter(lambda v, _: f"2^{math.log2(v):.0f}" if v > 0 else "0")
    elif log:
        set_scale(ax, "x", "log")
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0), numticks=8))
    elif np.unique(xs).size == 1:
        set_scale(ax, "x", "linear")
        axis.set_major_locator(FixedLocator([float(xs[0])]))
    else:
        pos = xs[xs > 0]
        if pos.size >= 2 and pos.max() / pos.min() > 50:
            if (xs <= 0).any():
                set_scale(ax, "x", "symlog", linthresh=float(pos.min()))
            else:
                set_scale(ax, "x", "log")
            axis.set_major_locator(LogLocator(numticks=5))
        else:
            set_scale(ax, "x", "linear")
            axis.set_major_locator(MaxNLocator(4))
    axis.set_major_formatter(plain)
    axis.set_minor_locator(NullLocator())
    _freeze_x_ticks(ax)


def _freeze_x_ticks(ax):
    """The x ticks the locator gives for the panel's final limits, drawn (on it and the panels
    sharing its x axis) as one line of tick marks and a text per label on the bottom panels,
    in place of matplotlib's ticks (five artists each): call once every series is plotted."""
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullLocator
    from matplotlib.transforms import blended_transform_factory
    ax.autoscale_view()
    lo, hi = sorted(ax.get_xlim())
    axis = ax.xaxis
    t = lambda v: float(axis.get_transform().transform([v])[0])
    tol = 1e-9 * abs(t(hi) - t(lo))
    values = [float(v) for v in axis.get_major_locator().tick_values(lo, hi)
              if np.isfinite(t(v)) and t(lo) - tol <= t(v) <= t(hi) + tol]
    labels = [axis.get_major_formatter()(v, i) for i, v in enumerate(values)]
    axis.set_major_locator(NullLocator())
    for panel in ax.get_shared_x_axes().get_siblings(ax):
        at = blended_transform_factory(panel.transData, panel.transAxes)
        panel.add_artist(Line2D(values, [0.0] * len(values), transform=at, ls="none", marker=3, ms=3.5, mew=0.8,
                                color="k", clip_on=False))                      # TICKDOWN
        spec = panel.get_subplotspec()
        if spec is None or spec.is_last_row():
            panel.add_artist(canvas.tick_labels([(v, -0.04) for v in values], labels, at, "center", "top",
                                                RC["xtick.labelsize"]))
        panel.xaxis.labelpad = RATE_LABEL_PAD[1]




LEGEND_FONT = MIN_FONT    # points
LEGEND_SPACING = 1.6      # line pitch of a legend, in font sizes (within the 0.2 in per entry _figure leaves)


def _legend(ax):
    """The panel's labelled series below it, one per line: a short stroke of the series' line or
    marker, then its label. Three artists however many entries (the strokes, their markers, the
    labels as one text of many lines): matplotlib's Legend lays every entry out as boxes of its
    own, a third of a figure's drawing time. ``ax.legend_texts`` keeps the labels."""
    from matplotlib.collections import LineCollection
    entries = ax.__dict__.pop("legend_entries", None)       # set by _line_series for this figure only
    if entries is None:
        handles, labels = ax.get_legend_handles_labels()
        styles = [_handle_style(h) for h in handles]
    else:
        styles, labels = [e[0] for e in entries], [e[1] for e in entries]
    ax.legend_texts = list(labels)
    if not labels:
        return
    fig = ax.figure
    box = ax.get_position()                                  # figure fraction (no layout engine)
    w_in, h_in = fig.get_size_inches()
    x0, top = box.x0 * w_in, box.y0 * h_in - LEGEND_GAP_IN               # inches
    pitch = LEGEND_SPACING * LEGEND_FONT * _font_height_em() / 72
    mid = lambda i: top - (i + 0.5) * pitch                  # the middle of line i
    strokes = [(i, st) for i, st in enumerate(styles) if st["ls"] not in ("none", "None", "")]
    fig.add_artist(LineCollection([[(x0 + 0.06, mid(i)), (x0 + 0.3, mid(i))] for i, _ in strokes],
                                  colors=[st["color"] for _, st in strokes],
                                  linestyles=[st["ls"] for _, st in strokes],
                                  linewidths=[st["lw"] for _, st in strokes], transform=fig.dpi_scale_trans))
    dots = [(i, st) for i, st in enumerate(styles) if st["marker"] not in (None, "none", "None", "")]
    for marker in dict.fromkeys(st["marker"] for _, st in dots):     # one collection per marker shape
        group = [(i, st) for i, st in dots if st["marker"] == marker]
        fig.add_artist(_marker_collection(marker, [2 / math.sqrt(math.pi) * st["ms"] for _, st in group],
                                          [(x0 + 0.18, mid(i)) for i, _ in group], fig.dpi_scale_trans,
                                          faces=[st["face"] for _, st in group], edges=[st["edge"] for _, st in group],
                                          lw=0.5))
    fig.text(x0 + 0.36, top, "\n".join(labels), transform=fig.dpi_scale_trans, fontsize=LEGEND_FONT, va="top",
             linespacing=LEGEND_SPACING)


@functools.lru_cache(maxsize=1)
def _font_height_em() -> float:
    """The text font's ascent plus descent in ems (OS/2 table, else hhea): matplotlib's line
    pitch is that times the font size times the line spacing."""
    from matplotlib.font_manager import FontProperties, findfont
    from matplotlib.ft2font import FT2Font
    font = FT2Font(findfont(FontProperties()))
    os2 = font.get_sfnt_table("OS/2")
    if os2 is None:
        hhea = font.get_sfnt_table("hhea")
        return (hhea["ascent"] - hhea["descent"]) / font.units_per_EM
    return (os2["sTypoAscender"] - os2["sTypoDescender"]) / font.units_per_EM


def _handle_style(h) -> dict:
    """A legend entry's stroke: the line's colour, style, width and marker, or a scatter's marker alone."""
    from matplotlib.lines import Line2D
    if isinstance(h, Line2D):
        marker = h.get_marker()
        return dict(color=h.get_color(), ls=h.get_linestyle(), lw=h.get_linewidth(), marker=marker,
                    ms=min(h.get_markersize(), 4), face=h.get_markerfacecolor(), edge=h.get_markeredgecolor())
    face, edge = h.get_facecolor(), h.get_edgecolor()
    return dict(color="none", ls="none", lw=0, marker="o", ms=3.5, face=face[0] if len(face) else "none",
                edge=edge[0] if len(edge) else "none")


TITLE_GAP = 0.08          # inches between a figure's title and its panels' titles


def _title(fig, text):
    """The figure's title, wrapped to its width (a narrow figure would cut a long one), the panels
    lowered where its lines need the room (a wrapped title overlapped the panels' own titles)."""
    import textwrap
    lines = textwrap.wrap(text, max(30, int(fig.get_figwidth() * 16)))
    fig.suptitle("\n".join(lines), fontsize=TITLE_FONT)
    height = fig.get_figheight()
    # suptitle's top at y = 0.98; a line is 1.2 font sizes; a panel's title its font and 4 points of pad
    need = 0.02 * height + len(lines) * 1.2 * TITLE_FONT / 72 + (1.2 * LABEL_FONT + 4) / 72 + TITLE_GAP
    if fig.subplotpars.top > 1 - need / height:
        fig.subplots_adjust(top=1 - need / height)


def _save(fig, path, points=None):
    """The figure as a PNG, drawn under RC (matplotlib makes most ticks while drawing); ``points``:
    [(axes, [(x, y, case, label)])] in data coordinates, written beside it as the pixels they
    were drawn at (points_file)."""
    from matplotlib import rc_context
    cv = canvas.canvas(fig)
    dpi = fig.dpi
    with rc_context(RC):
        fig.set_dpi(DPI)             # what savefig(dpi=DPI) draws at; its PNG writer is Pillow's (png.py says why not)
        try:
            cv.draw()
            # RGB: the figure is opaque (white), and an alpha of 255 everywhere is a quarter of the bytes to compress
            png.write(Path(path), np.asarray(cv.buffer_rgba())[..., :3], dpi=DPI)
            if points is not None:
                _write_points(Path(path), fig, points)
        finally:
            fig.set_dpi(dpi)         # as savefig leaves it: a figure returned to a caller keeps its own


def points_file(png_path: Path) -> Path:
    """Where a figure's case points are listed: beside its PNG, ``<name>.points.json``."""
    return Path(png_path).with_suffix(".points.json")


def _write_points(path: Path, fig, points: list):
    """The case points of a drawn figure as [[x, y, case, label]] in its PNG's pixels (origin top
    left), so a page can name each point and open its case (report.html's image map)."""
    height = fig.bbox.height
    out = []
    for ax, pts in points:
        if not pts:
            continue
        xy = ax.transData.transform([(p[0], p[1]) for p in pts])
        out += [[int(round(x)), int(round(height - y)), str(p[2]), str(p[3])]
                for (x, y), p in zip(xy, pts) if math.isfinite(x) and math.isfinite(y)]
    with atomic(points_file(path)) as tmp:
        tmp.write_text(json.dumps(out, separators=(",", ":")) + "\n", encoding="utf-8")


def chunks(items, n=MAX_LEGEND):
    """``items`` in lists of at most ``n`` (one empty list when there are none)."""
    items = list(items)
    return [items[i:i + n] for i in range(0, len(items), n)] or [[]]


def _title_panel(ax, text):
    """A panel's title at a fixed height (matplotlib would otherwise measure the panel's every
    tick label to place it: nothing is drawn above a panel here)."""
    ax.set_title(text, fontsize=LABEL_FONT, y=1.0, pad=4)


def _line(ax, x, y, **kw):
    """A Line2D of (x, y) added to ``ax`` as ``ax.plot`` adds it, without plot's parsing of its
    arguments (a third of a series' cost); the caller sets the axes' limits."""
    from matplotlib.lines import Line2D
    return ax.add_line(Line2D(x, y, **kw))


def _strokes(ax, lines, clip_on: bool):
    """Polylines ``lines`` = [(vertices, colour, line style, width)] in ``ax`` as LineCollections
    (no data limits taken), with Line2D's caps: projecting on solid lines, butt on dashed ones
    (projecting caps would lengthen every dash by a line width and nearly close a dotted line's gaps)."""
    from matplotlib.collections import LineCollection
    for cap, group in (("projecting", [ln for ln in lines if ln[2] in ("-", "solid")]),
                       ("butt", [ln for ln in lines if ln[2] not in ("-", "solid")])):
        if group:
            ax.add_collection(LineCollection([ln[0] for ln in group], colors=[ln[1] for ln in group],
                                             linestyles=[ln[2] for ln in group], linewidths=[ln[3] for ln in group],
                                             capstyle=cap, joinstyle="round", clip_on=clip_on), autolim=False)


def _marker_collection(marker: str, ms, xy, transform, faces, edges, lw: float, **kw):
    """Markers of one shape at ``xy`` (in ``transform``'s coordinates), ``ms`` their diameters in
    points (one, or one each) as Line2D's ``markersize``: a CircleCollection for "o", else the
    marker's path as scatter() draws it."""
    from matplotlib.collections import CircleCollection, PathCollection
    from matplotlib.markers import MarkerStyle
    ms = np.broadcast_to(np.asarray(ms, float), (len(xy),))
    if marker == "o":
        return CircleCollection(math.pi / 4 * ms ** 2, offsets=xy, offset_transform=transform, facecolors=faces,
                                edgecolors=edges, linewidths=lw, **kw)
    from matplotlib.transforms import IdentityTransform
    m = MarkerStyle(marker)
    # a unit marker's path scaled by sqrt(size) points, as scatter() makes it (the paths' own transform
    # the identity: a figure or axes would otherwise give it theirs); sized to the circle of that diameter
    coll = PathCollection([m.get_path().transformed(m.get_transform())], sizes=math.pi / 4 * ms ** 2, offsets=xy,
                          offset_transform=transform, facecolors=faces, edgecolors=edges, linewidths=lw, **kw)
    coll.set_transform(IdentityTransform())
    return coll


def _dots(ax, xy, ms: float, faces, edges, lw: float, zorder: float, markers=None):
    """Markers at data points ``xy`` (round, or ``markers`` one each), one collection per shape,
    sized as Line2D's ``markersize`` ``ms`` (a diameter in points), unclipped, on whole pixels as Line2D's."""
    markers = ["o"] * len(xy) if markers is None else list(markers)
    faces = faces if isinstance(faces, (list, tuple)) else [faces] * len(xy)
    edges = edges if isinstance(edges, (list, tuple)) else [edges] * len(xy)
    for marker in dict.fromkeys(markers):
        at = [i for i, m in enumerate(markers) if m == marker]
        ax.add_collection(_marker_collection(marker, ms, [xy[i] for i in at], ax.transData, [faces[i] for i in at],
                                             [edges[i] for i in at], lw, clip_on=False, zorder=zorder, snap=True),
                          autolim=False)


SERIES_MS = 3             # a series' marker diameter, in points (as Line2D's markersize)


def _line_series(ax, series, styles, i) -> list:
    """Rate ``i`` of each series of ``series`` against x in ``ax``; returns the x values drawn.
    Every series' line is one LineCollection and every marker one CircleCollection (drawn over
    the lines): two artists a panel, not a Line2D per series (a Line2D's making and drawing was
    the larger part of these figures' cost); the legend reads ``ax.legend_entries``."""
    from matplotlib.colors import to_rgba
    xs, lines, dots, entries = [], [], [], []
    for k, (label, pts) in enumerate(series.items()):
        given = dict(styles.get(label, {}))
        shown = given.pop("legend", label)          # its legend entry ('_': none)
        own = style(k)                 # the k-th series' colour, marker and dash
        color = to_rgba(given.pop("color", own["color"]))
        marker = given.pop("marker", own["marker"])
        ls, lw = given.pop("linestyle", given.pop("ls", own["ls"])), given.pop("lw", 0.9)
        if given:
            raise ValueError(f"series {label!r}: unknown style keys {sorted(given)} (color, marker, linestyle, lw, "
                             "legend)")
        if not str(shown).startswith("_"):
            entries.append((dict(color=color, ls=ls, lw=lw, marker=marker, ms=SERIES_MS, face=color, edge=color),
                            shown))
        pts = sorted(p for p in pts if metrics.defined(p[1 + i]))    # undefined: left out, not 0
        xs += [p[0] for p in pts]
        if len(pts) > 1 and ls not in ("none", "None", ""):
            lines.append(([(p[0], p[1 + i]) for p in pts], color, ls, lw))
        dots += [((p[0], p[1 + i]), color, marker) for p in pts]
    _strokes(ax, lines, clip_on=False)
    if dots:
        # the data limits from the points themselves (the x axis autoscales to them): add_collection
        # would find them by transforming every path through the axes' scales
        ax.update_datalim([d[0] for d in dots])
        _dots(ax, [d[0] for d in dots], SERIES_MS, [d[1] for d in dots], [d[1] for d in dots], 1.0, 2.01,
              [d[2] for d in dots])
    ax.legend_entries = entries
    return xs


def draw_lines(path, title, columns, ylabels=("acne rate", "peter-panning rate"), xlog2=False):
    """A grid of panels: a row per rate, a column per entry of ``columns`` =
    [(column title, x label, {label: [(x, rate0, rate1, ...)]}, {label: plot keywords})] (keyword
    ``legend``: the series' legend entry in place of its label, '_' for none);
    a column's panels share their x axis (the union of its rates' defined points)."""
    nleg = max(sum(1 for k in c[2] if not str(c[3].get(k, {}).get("legend", k)).startswith("_")) for c in columns)
    fig, axes = _figure(len(columns), len(ylabels), legend_rows=nleg, sharey=True, sharex=True)
    for j, (ctitle, xlabel, series, styles) in enumerate(columns):
        xs = []
        for i, ylabel in enumerate(ylabels):
            ax = axes[i, j]
            xs += _line_series(ax, series, styles, i)
            _rate_axis(ax)
            if j == 0:
                ax.set_ylabel(ylabel, fontsize=LABEL_FONT)
        _x_scale(axes[-1, j], xs, xlog2)       # shared: once per column
        _title_panel(axes[0, j], ctitle)
        axes[-1, j].set_xlabel(xlabel, fontsize=LABEL_FONT)
        _legend(axes[-1, j])
    _title(fig, title)
    _save(fig, path)
    return fig


# points are Line2D markers, not scatter()'s PathCollection (a tenth of the cost to make and draw)
POINT_MS = 4.7            # a case's point, in points (scatter's s=10 and its 1.5-point edge)


def draw_pareto(path, title, panels, front):
    """Error rate (symlog) against bytes read (log): panels = [{scheme: [(bytes, error)]}], each with the
    frontier ``front`` [(bytes, error)] over every case."""
    fig, axes = _figure(len(panels), 1, width=4.2, height=3.0, legend_rows=max(len(p) for p in panels) + 1,
                        sharey=True)
    points = []
    for ax, series in zip(axes[0], panels):
        points.append((ax, [(p[0], p[1], p[2], p[3]) for _, pts in series.values() for p in pts if len(p) > 3]))
        for label, (k, pts) in series.items():
            st = style(k)
            _line(ax, [p[0] for p in pts], [p[1] for p in pts], ls="none", marker=st["marker"], ms=POINT_MS, mew=0,
                  color=st["color"], label=label, clip_on=False)
        _line(ax, [p[0] for p in front], [p[1] for p in front], color="k", ls="-", lw=0.8,
              label="on the frontier (error, bytes, rays)")
        _line(ax, [p[0] for p in front], [p[1] for p in front], ls="none", marker="o", ms=6.3, mfc="none", mec="k",
              mew=0.6, clip_on=False)
        _x_scale(ax, [], log=True)
        _rate_axis(ax)
        ax.set_xlabel("bytes its lookup reads (stored width)", fontsize=LABEL_FONT)
        if ax is axes[0][0]:
            ax.set_ylabel("error rate: (acne + peter-pan) / receivers", fontsize=LABEL_FONT)
        _legend(ax)
    _title(fig, title)
    _save(fig, path, points)
    return fig


TRADEOFF_KEY = "solid: one world bias, dotted: one k texel"


def _steps_post(x, y) -> np.ndarray:
    """The vertices of a steps-post curve through (x, y), as Line2D's ``drawstyle="steps-post"`` draws it."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    v = np.empty((max(2 * x.size - 1, 0), 2))
    v[0::2, 0], v[0::2, 1] = x, y
    v[1::2, 0], v[1::2, 1] = x[1:], y[:-1]
    return v


def _tradeoff_maps(ax, maps):
    """Each map's two curves and its case points in ``ax`` as three collections (solid, dotted,
    points), with a legend entry per map (its colour, the solid stroke); _rate_axis sets both limits."""
    from matplotlib.colors import to_rgba
    colours = [to_rgba(style(k)["color"]) for _, k, _, _, _ in maps]
    shapes = [style(k)["marker"] for _, k, _, _, _ in maps]
    _strokes(ax, [(_steps_post(*m[2 + i]), c, ls, lw) for i, (lw, ls) in enumerate(((1.0, "-"), (0.8, ":")))
                  for m, c in zip(maps, colours)], clip_on=True)
    pts = [(p[:2], c, mk) for m, c, mk in zip(maps, colours, shapes) for p in m[4]]
    if pts:
        _dots(ax, [p[0] for p in pts], 3.5, [p[1] for p in pts], "k", 0.3, 3, [p[2] for p in pts])
    ax.legend_entries = [(dict(color=c, ls="-", lw=1.0, marker=mk, ms=3.5, face=c, edge="k"), m[0])
                         for m, c, mk in zip(maps, colours, shapes)]


def draw_tradeoff(path, title, panels):
    """Peter-panning rate against acne rate, both symlog: panels = [(panel title, [(label, colour index,
    world curve (x, y), texel curve (x, y), case points [(x, y)])])]. A map's two curves share its
    colour (solid: one world bias, dotted: one k texel, the title says so) and one legend entry; a
    panel whose maps are the previous panel's has no legend of its own."""
    fig, axes = _figure(len(panels), 1, width=3.8, height=3.4, legend_rows=max(len(p[1]) for p in panels),
                        sharey=True)
    shown, points = None, []
    for ax, (ptitle, maps) in zip(axes[0], panels):
        _tradeoff_maps(ax, maps)
        points.append((ax, [(p[0], p[1], p[2], p[3]) for m in maps for p in m[4] if len(p) > 3]))
        _rate_axis(ax, "x")
        _rate_axis(ax, "y")
        ax.set_xlabel("acne rate", fontsize=LABEL_FONT)
        if ax is axes[0][0]:
            ax.set_ylabel("peter-panning rate", fontsize=LABEL_FONT)
        _title_panel(ax, ptitle)
        entries = [(m[0], m[1]) for m in maps]
        if entries != shown:
            _legend(ax)
            shown = entries
    _title(fig, f"{title} ({TRADEOFF_KEY})")
    _save(fig, path, points)
    return fig


# ------------------------------------------------------------------ what to draw

def _unit(sweep_key: str) -> tuple:
    """'bias [texel]' -> ('bias', 'texel'); 'K' -> ('K', 'K')."""
    m = re.fullmatch(r"(.*) \[(.*)\]", sweep_key)
    return (m.group(1), m.group(2)) if m else (sweep_key, sweep_key)


def _others(params: str, name: str) -> str:
    """A scheme's parameters without the swept one."""
    return re.sub(rf"(^| ){re.escape(name)}=\S+(?: (?:texel|range|world))?", "", params).strip()


def _res_text(rs) -> str:
    res = sorted({r["resolution"] for r in rs})
    return f"R = {res[0]}" if len(res) == 1 else "R = " + ", ".join(map(str, res))


def _label(r, multi=()):
    lab = f"{r['scheme']} {r['preset'] or params_label(r['params'])}".strip()
    return " ".join([lab] + [r.get(k, "") for k in multi])[:48]


def _groups(rows, keys):
    out = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def plot_jobs(folder: Path, rows: list, curves: list = ()) -> list:
    """The figures of a run as (function, arguments) pairs, each writing one PNG into ``folder``.
    ``curves``: per map and format, (meta row, world curve (x, y), texel curve (x, y)) as rates."""
    folder = Path(folder)
    jobs = []
    multi = tuple(k for k in ("filter", "format", "cascade_layout") if len({r.get(k, "") for r in rows}) > 1)
    for (scene, light), rs in sorted(_groups(rows, ("scene", "light")).items()):
        views = sorted({r["view"] for r in rs})
        for view in views:
            vr = [r for r in rs if r["view"] == view]
            tag = slug(f"{scene}_{light}_{view}")
            where = f"{scene}, light {light}, {view}"
            cs = [c for c in curves if (c[0]["scene"], c[0]["light"], c[0]["view"]) == (scene, light, view)]
            for kind, job in (("vs_bias", _bias_job(vr, where, multi)), ("vs_resolution", _resolution_job(vr, where, multi)),
                              ("pareto", _pareto_job(vr, where)), ("tradeoff", _tradeoff_job(vr, where, cs))):
                if job is not None:
                    jobs.append((job[0], (folder / f"{kind}_{tag}.png",) + job[1]))
        if len(views) > 1:
            job = _texels_job(rs, scene, light, views, multi)
            if job is not None:
                jobs.append((job[0], (folder / f"vs_texels_{slug(f'{scene}_{light}')}.png",) + job[1]))
    return jobs


def _bias_job(vr: list, where: str, multi: tuple):
    """Rates against the swept parameter, a column per unit, at the view's largest resolution:
    (draw function, arguments after the path), or None when no scheme sweeps more than one value."""
    rmax = max(r["resolution"] for r in vr)
    swept = {}
    for r in vr:
        if r["resolution"] == rmax and not r["preset"] and r["sweep_key"]:
            swept.setdefault((r["scheme"], r["sweep_key"]), set()).add(r["sweep_value"])
    units = {}
    for r in vr:
        # schemes whose sweep has one value have no curve: the summary and the other plots show them
        if r["resolution"] == rmax and not r["preset"] and len(swept.get((r["scheme"], r["sweep_key"]), ())) > 1:
            name, unit = _unit(r["sweep_key"])
            others = params_label(_others(r["params"], name))
            lab = f"{r['scheme']}: {name}" + (f" ({others})" if others else "")
            lab = " ".join([lab] + [r.get(k, "") for k in multi])[:52]
            units.setdefault(unit, {}).setdefault(lab, []).append((r["sweep_value"], r["acne_rate"], r["peterpan_rate"]))
    columns = []
    for unit, series in sorted(units.items()):
        series = {k: v for k, v in series.items() if len(v) > 1}
        lengths = unit in ("texel", "world", "range")
        for part in (chunks(sorted(series)) if series else []):
            columns.append((f"lengths in {unit}" if lengths else f"parameter {unit} (no unit)",
                            f"parameter value [{unit}]" if lengths else unit, {k: series[k] for k in part}, {}))
    if not columns:
        return None
    return draw_lines, (f"{where}, R = {rmax}: rates against each scheme's swept parameter (one column per unit)",
                        columns)


def _resolution_job(vr: list, where: str, multi: tuple):
    """Rates against map resolution, a series per scheme instance (None: no instance at two resolutions)."""
    series = {}
    for r in vr:
        series.setdefault(_label(r, multi), []).append((r["resolution"], r["acne_rate"], r["peterpan_rate"]))
    series = {k: v for k, v in series.items() if len(v) > 1}
    if not series:
        return None
    parts = chunks(series)
    columns = [(f"schemes {i + 1} of {len(parts)}" if len(series) > MAX_LEGEND else "schemes",
                "map resolution R (R x R texels per face)", {k: series[k] for k in part}, {})
               for i, part in enumerate(parts)]
    return draw_lines, (f"{where}, {_res_text(vr)}", columns, ("acne rate", "peter-panning rate"), True)


def _pareto_job(vr: list, where: str):
    """What accuracy costs: every scored case's error rate against the bytes its lookup reads, the
    cases on the frontier (dsm.report.frontier: error, bytes and rays; time never decides) circled.
    None for rows without costs (a run from before them)."""
    scored = [r for r in vr if metrics.defined(r["error_rate"])]
    if not scored or not frontier.has_costs(scored):
        return None
    nbytes = lambda r: r["map_bytes"] + r["page_table_bytes"]
    schemes = sorted({r["scheme"] for r in scored})
    panels = [{s: (schemes.index(s), [(nbytes(r), r["error_rate"], r["case"], _label(r)) for r in scored if r["scheme"] == s])
               for s in part} for part in chunks(schemes, MAX_LEGEND - 1)]
    marks = frontier.on_frontier(frontier.points_from_rows(scored))
    front = sorted((nbytes(r), r["error_rate"]) for r, m in zip(scored, marks) if m)
    return draw_pareto, (f"{where}, {_res_text(scored)}: error rate against memory, every case", panels, front)


def _tradeoff_job(vr: list, where: str, cs: list):
    """The exact trade-off of one bias (the oracle's curves ``cs`` of the view), with the nearest cases on it."""
    if not cs:
        return None
    panels = []
    for res in sorted({c[0]["resolution"] for c in cs}):
        maps = []
        for k, (meta, cw, ck) in enumerate(c for c in cs if c[0]["resolution"] == res):
            pts = [(r["acne_rate"], r["peterpan_rate"], r["case"], _label(r)) for r in vr if r["filter"] == "nearest"
                   and r["resolution"] == res and all(r[x] == meta[x] for x in ("culling", "format"))
                   and metrics.defined(r["acne_rate"]) and metrics.defined(r["peterpan_rate"])]
            lab = f"{meta['format']}" + (f" {meta['culling']}" if meta["culling"] != "none" else "")
            maps.append((lab, k, cw, ck, pts))
        for i, part in enumerate(chunks(maps, MAX_LEGEND // 2)):
            panels.append((f"R = {res}" + (f" ({i + 1})" if len(maps) > MAX_LEGEND // 2 else ""), part))
    return draw_tradeoff, (f"{where}: exact trade-off of one bias for the map (lines), nearest cases (points)",
                           panels)


VIEW_LINES = ("-", "--", ":", "-.")
VIEW_LINE_NAMES = ("solid", "dashed", "dotted", "dash-dot")


def _texels_job(rs: list, scene: str, light: str, views: list, multi: tuple):
    """Views at equal memory: error rates against the view's total texels, colour per instance,
    line style per view (an instance's views kept in one panel)."""
    tex, styles, inst_of = {}, {}, {}
    insts = sorted({_label(r, multi) for r in rs})
    named = {}                               # instance -> its series in the legend: its first view's
    for r in sorted(rs, key=lambda r: views.index(r["view"])):
        lab = f"{r['view']}: {_label(r, multi)}"[:52]
        inst = inst_of[lab] = _label(r, multi)         # the instance, also when the label was cut
        named.setdefault(inst, lab)
        own = style(insts.index(inst))
        styles[lab] = {"color": own["color"], "marker": own["marker"], "linestyle": VIEW_LINES[views.index(r["view"]) % 4],
                       "legend": inst if named[inst] == lab else "_"}
    for r in rs:                             # the series in the rows' order, as before
        tex.setdefault(f"{r['view']}: {_label(r, multi)}"[:52], []).append(
            (r["total_texels"], r["error_rate"], r["seam_error_rate"]))
    by_inst = chunks(insts, MAX_LEGEND)     # a legend entry per instance, not per view
    columns = [(f"schemes {i + 1} of {len(by_inst)}", "total texels of the view (all faces)",
                {k: v for k, v in tex.items() if inst_of[k] in part}, styles) for i, part in enumerate(by_inst)]
    columns = [c for c in columns if c[2]]
    if not columns:
        return None
    return draw_lines, (f"{scene}, light {light}, views {', '.join(views)}, {_res_text(rs)}: views at equal memory "
                        "(colour: scheme; line: " + ", ".join(f"{v} {VIEW_LINE_NAMES[i % 4]}" for i, v in enumerate(views)) + ")",
                        columns,
                        ("error rate", f"error rate within {metrics.SEAM_TEXELS:g} texels of a seam"), True)


# ------------------------------------------------------------------ oracle curves on disk

def decimate(x: np.ndarray, y: np.ndarray, steps: int = 600) -> tuple:
    """A monotone step curve reduced to the points that move it visibly on symlog axes."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if x.size <= 2:
        return x.astype(np.float32), y.astype(np.float32)
    t = lambda v: np.log10(1 + v / LINTHRESH) / np.log10(1 + 1 / LINTHRESH)
    q = np.round(t(x) * steps).astype(np.int64) * (steps + 1) + np.round(t(y) * steps).astype(np.int64)
    keep = np.ones(x.size, bool)
    keep[1:] = q[1:] != q[:-1]
    keep[-1] = True
    return x[keep].astype(np.float32), y[keep].astype(np.float32)


CURVE_META = ("scene", "light", "view", "resolution", "culling", "format")


def curve_rates(row, cw, ck) -> tuple:
    """(meta, world (x, y), texel (x, y)) as decimated rates, from the oracle's exact curves."""
    meta = {k: row[k] for k in CURVE_META}
    rates = lambda c: decimate(c.acne / max(c.n_lit, 1), c.peterpan / max(c.n_shadowed, 1))
    return meta, rates(cw), rates(ck)


def save_curves(path: Path, curves: list):
    """oracle_curves.npz: the trade-off curves as decimated rates (both rates defined only)."""
    arrays = {"meta": np.array(json.dumps([c[0] for c in curves]))}
    for i, (_, w, k) in enumerate(curves):
        arrays.update({f"w{i}_x": w[0], f"w{i}_y": w[1], f"k{i}_x": k[0], f"k{i}_y": k[1]})
    _atomic_save(Path(path), lambda f: np.savez_compressed(open(f, "wb"), **arrays))


def load_curves(path: Path) -> list:
    """The curves save_curves wrote into ``path``: (meta, world (x, y), texel (x, y)) each; [] without the file."""
    if not Path(path).is_file():
        return []
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        return [(m, (z[f"w{i}_x"], z[f"w{i}_y"]), (z[f"k{i}_x"], z[f"k{i}_y"])) for i, m in enumerate(meta)]
