"""Gradient images side by side: the reference's per-pixel difference, each technique's tangent, the
projective integrator's, one row per parameter (``gradients.png``), each panel on its own symmetric
colour scale (its largest magnitude; the scale is printed in the panel's title)."""
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
