"""Gradient images side by side: the reference's per-pixel difference, each technique's tangent, the
projective integrator's, one row per parameter (``gradients.png``), each panel on its own symmetric
colour scale (its largest magnitude; the scale is printed in the panel's title); and the cost at
equal error (``equal_error.png``): path tracing's error against its ms, each technique's point."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def panel_title(name: str, img: np.ndarray) -> str:
    """A panel's title: its name and colour scale (the image's largest magnitude)."""
    return f"{name}\n|max| {np.max(np.abs(img)):.3g}"


def draw(path: Path, panels: dict, window: float):
    """Write ``gradients.png``: ``panels`` maps a parameter to [(name, (N, N) image)], row y up."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    rows = list(panels)
    cols = max(len(v) for v in panels.values())
    fig = Figure(figsize=(2.1 * cols, 2.3 * len(rows)), dpi=100)
    FigureCanvasAgg(fig)
    for i, p in enumerate(rows):
        for j, (name, img) in enumerate(panels[p]):
            ax = fig.add_subplot(len(rows), cols, i * cols + j + 1)
            m = float(np.max(np.abs(img))) or 1.0
            ax.imshow(img, origin="lower", cmap="RdBu_r", vmin=-m, vmax=m, extent=(-window, window, -window, window))
            ax.set_title(panel_title(name, img) + (f"\nd/d {p}" if j == 0 else ""), fontsize=7)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path)


CURVE_STYLES = ["o-", "^--", "s-."]      # one per integrator


def draw_equal_error(path: Path, curves, rows):
    """Write ``equal_error.png``: relative error against ms per gradient (log-log), each integrator's curve
    over its spp counts (labelled), each technique's point; one panel per parameter."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    params = list(dict.fromkeys(c[0].param for c in curves))
    fig = Figure(figsize=(6.4, 4.6 * max(len(params), 1)), dpi=100)
    FigureCanvasAgg(fig)
    for i, p in enumerate(params):
        ax = fig.add_subplot(len(params), 1, i + 1)
        mine = [c for c in curves if c[0].param == p]
        for c, style in zip(mine, CURVE_STYLES * len(mine)):
            pts = [(q.ms, q.rel_rms_error, q.spp) for q in c if q.rel_rms_error]
            ax.plot([x for x, _, _ in pts], [y for _, y, _ in pts], style, color="black", lw=1, ms=3,
                    label=f"{c[0].integrator} (spp)")
            for x, y, spp in pts:
                ax.annotate(str(spp), (x, y), fontsize=6, xytext=(3, 3), textcoords="offset points")
        if mine and mine[0][0].truth:     # below the truth's own error the curves are not resolved
            t = mine[0][0]
            ax.axhline(t.truth_error / abs(t.truth), color="grey", ls=":", lw=1, label="the truth's own error")
        shown = {}
        for r in rows:           # a technique's point is the same against every integrator's curve
            if r.param == p and r.error and r.technique not in shown:
                shown[r.technique] = ax.plot([r.ms], [r.error], "s", ms=5, label=r.technique)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ms per gradient")
        ax.set_ylabel("relative error of d loss / d " + p)
        ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path)
