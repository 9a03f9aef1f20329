"""Gradient images side by side: the reference's per-pixel difference, each technique's tangent, the
projective integrator's, rows of at most MAX_COLUMNS panels per parameter (``gradients.png``), each
panel on its own symmetric colour scale (its largest magnitude; the scale is printed in the panel's
title); and the cost at equal error (``equal_error.png``): path tracing's error against its ms, each
technique's point. Drawn as the report's figures (dsm.report.figures): at DPI, shown at its pixel
size, its smallest text MIN_FONT points (9 as shown)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..report.figures import DPI, MIN_FONT, PNG, style
from ..report.io import save_png

MAX_COLUMNS = 5            # panels a row: 5 of PANEL_INCHES fit a 1280 px window at DPI
PANEL_INCHES = 1.8


def panel_title(name: str, img: np.ndarray) -> str:
    """A panel's title: its name and colour scale (the image's largest magnitude)."""
    return f"{name}\n|max| {np.max(np.abs(img)):.3g}"


def layout(panels: dict) -> tuple:
    """(rows, columns) of the figure: each parameter's panels on ceil(n / MAX_COLUMNS) rows of their own."""
    cols = min(MAX_COLUMNS, max(len(v) for v in panels.values()))
    return sum(math.ceil(len(v) / cols) for v in panels.values()), cols


def draw(path: Path, panels: dict, window: float):
    """Write ``gradients.png``: ``panels`` maps a parameter to [(name, (N, N) image)], row y up."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    n_rows, cols = layout(panels)
    fig = Figure(figsize=(PANEL_INCHES * cols, 2.1 * n_rows))
    FigureCanvasAgg(fig)
    row = 0
    for p, items in panels.items():
        for j, (name, img) in enumerate(items):
            ax = fig.add_subplot(n_rows, cols, (row + j // cols) * cols + j % cols + 1)
            m = float(np.max(np.abs(img))) or 1.0
            ax.imshow(img, origin="lower", cmap="RdBu_r", vmin=-m, vmax=m, extent=(-window, window, -window, window))
            ax.set_title(panel_title(name, img) + (f"\nd/d {p}" if j == 0 else ""), fontsize=MIN_FONT)
            ax.set_xticks([])
            ax.set_yticks([])
        row += math.ceil(len(items) / cols)
    fig.tight_layout()
    save_png(path, lambda f, fmt: fig.savefig(f, dpi=DPI, format=fmt, pil_kwargs=PNG))


CURVE_STYLES = ["o-", "^--", "s-."]      # one per integrator


def _say_undefined(ax, param: str):
    """A panel of no defined relative error: the sentence in place of the axes."""
    ax.set_axis_off()
    ax.text(0.5, 0.5, f"d loss / d {param}: every relative error is undefined\n(the truth is 0 over the pixels "
            "the camera sees, or no technique's error is defined)", ha="center", va="center", fontsize=MIN_FONT,
            transform=ax.transAxes)


def draw_equal_error(path: Path, curves, rows):
    """Write ``equal_error.png``: relative error against ms per gradient (log-log), each integrator's curve
    over its spp counts (labelled), each technique's point; one panel per parameter."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    params = list(dict.fromkeys(c[0].param for c in curves))
    fig = Figure(figsize=(6.4, 4.6 * max(len(params), 1)))
    FigureCanvasAgg(fig)
    for i, p in enumerate(params):
        ax = fig.add_subplot(len(params), 1, i + 1)
        mine = [c for c in curves if c[0].param == p]
        for c, curve_style in zip(mine, CURVE_STYLES * len(mine)):
            pts = [(q.ms, q.rel_rms_error, q.spp) for q in c if q.rel_rms_error]
            ax.plot([x for x, _, _ in pts], [y for _, y, _ in pts], curve_style, color="black", lw=1, ms=3,
                    label=f"{c[0].integrator} (spp)")
            for x, y, spp in pts:
                ax.annotate(str(spp), (x, y), fontsize=MIN_FONT, xytext=(3, 3), textcoords="offset points")
        if mine and mine[0][0].truth:     # below the truth's own error the curves are not resolved
            t = mine[0][0]
            ax.axhline(t.truth_error / abs(t.truth), color="grey", ls=":", lw=1, label="the truth's own error")
        shown = {}
        for r in rows:           # a technique's point is the same against every integrator's curve
            if r.param == p and r.error and r.technique not in shown:
                st = style(len(shown))
                shown[r.technique] = ax.plot([r.ms], [r.error], st["marker"], color=st["color"], ms=6,
                                             mec="black", mew=0.5, label=r.technique)
        if not any(np.any(np.asarray(line.get_ydata(), float) > 0) for line in ax.get_lines()):
            _say_undefined(ax, p)      # a log axis of no positive value does not exist
            continue
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ms per gradient")
        ax.set_ylabel("relative error of d loss / d " + p)
        ax.legend(fontsize=MIN_FONT, ncol=2)
        ax.tick_params(labelsize=MIN_FONT)
    fig.tight_layout()
    save_png(path, lambda f, fmt: fig.savefig(f, dpi=DPI, format=fmt, pil_kwargs=PNG))
