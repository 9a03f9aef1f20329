"""Gradient images side by side: the reference's per-pixel difference, each technique's tangent, the
projective integrator's, rows of at most MAX_COLUMNS panels per parameter (``gradients.png``), each
panel on its own symmetric colour scale (its largest magnitude; the scale is printed in the panel's
title). Drawn as the report's figures (dsm.report.figures): at DPI, shown at its pixel size, its
smallest text MIN_FONT points (9 as shown)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..report.figures import DPI, MIN_FONT, PNG

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
    fig.savefig(path, dpi=DPI, format="png", pil_kwargs=PNG)
