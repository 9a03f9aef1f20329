"""The leaderboard's figure: each contender's error rate against the scene's unit and against its offset.

Drawn as the report's figures are (dsm.report.figures): matplotlib's Agg canvas without pyplot,
a symlog rate axis from 0 to 1 (linear below 1e-4, so zero shows), at most MAX_LEGEND legend
entries per panel (more contenders go to more rows of panels), at the report's DPI (shown at its
pixel size, its MIN_FONT text reads as 9 points), each contender in the report's series style (colour,
marker and dash: report.figures.style), the oracle's per-texel floor a thick black dashed line
named on the panel, PNG with fast compression. The numbers drawn are :func:`series`, which the
page's tables print too.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..report.figures import DPI, LINTHRESH, LABEL_FONT, MAX_LEGEND, MIN_FONT, PNG, RC, style
from . import ranking

UNITS = ("cm", "m", "km")
FILE = "scale.png"


def series(doc: dict) -> dict:
    """{"unit": (unit labels, {contender: error rates}), "offset": (offset labels, {contender: error rates})}:
    mean error rate (the oracle's per-texel floor) per unit at the origin, and per offset at the far unit."""
    by_unit = ranking.error_by(doc, lambda r: r["unit"])
    units = [u for u in UNITS if any(u in d for d in by_unit.values())]
    out = {"unit": (units, {c: [d.get(u) for u in units] for c, d in sorted(by_unit.items())})}
    far_unit = doc.get("far_unit")
    if far_unit:
        offs = ranking.offsets(doc)
        by_off = ranking.error_by(doc, ranking.offset_of, keep=lambda r: r["unit"] == far_unit)
        out["offset"] = (offs, {c: [d.get(o) for o in offs] for c, d in sorted(by_off.items())})
    return out


def draw(data: dict, far_unit: str | None = None):
    """The figure (a matplotlib Figure, not saved) of :func:`series`' numbers: a row of panels per axis
    (unit, then offset) and group of at most MAX_LEGEND contenders, one column (it fits a page's width)."""
    from matplotlib import rc_context
    from matplotlib.figure import Figure
    names = sorted(data["unit"][1])
    order = [n for n in names if n != "oracle"]          # a contender's style: its place among the contenders
    groups = [names[i:i + MAX_LEGEND] for i in range(0, len(names), MAX_LEGEND)] or [[]]
    kinds = [k for k in ("unit", "offset") if k in data]
    with rc_context(RC):
        fig = Figure(figsize=(7.0, 3.0 * len(groups) * len(kinds)))
        # panel (kind j, group i) is row j * len(groups) + i of the one column
        rows = fig.subplots(len(groups) * len(kinds), 1, squeeze=False)
        axes = [[rows[j * len(groups) + i][0] for j in range(len(kinds))] for i in range(len(groups))]
        for j, kind in enumerate(kinds):
            labels, values = data[kind]
            for i, group in enumerate(groups):
                ax = axes[i][j]
                for name in group:
                    y = [math.nan if v is None else v for v in values.get(name, [None] * len(labels))]
                    if name == "oracle":
                        ax.plot(range(len(labels)), y, color="k", lw=2.2, ls="--", label=name, zorder=3)
                        ax.annotate("oracle floor (per-texel)", (len(labels) - 1, y[-1]), xytext=(-4, 4),
                                    textcoords="offset points", ha="right", va="bottom", fontsize=MIN_FONT)
                        continue
                    st = style(order.index(name))
                    ax.plot(range(len(labels)), y, marker=st["marker"], ms=4, lw=1.2, label=name, ls=st["ls"],
                            color=st["color"])
                ax.set_yscale("symlog", linthresh=LINTHRESH, linscale=0.6)
                ax.set_ylim(0, 1)
                ax.set_xticks(range(len(labels)), labels)
                ax.set_xlabel("scene unit (at the origin)" if kind == "unit" else f"offset (world units, at {far_unit})",
                              fontsize=LABEL_FONT)
                ax.set_ylabel("error rate", fontsize=LABEL_FONT)
                ax.legend(fontsize=MIN_FONT, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False,
                          handlelength=3)
        fig.subplots_adjust(wspace=0.6, hspace=0.45)
    return fig


def write(doc: dict, out: Path) -> Path:
    """Draw :func:`series` of a result and write it as ``scale.png`` in ``out``; returns its path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    fig = draw(series(doc), doc.get("far_unit"))
    FigureCanvasAgg(fig)
    path = Path(out) / FILE
    # tight: the legends sit right of their panels, outside the axes' layout
    fig.savefig(path, dpi=DPI, format="png", bbox_inches="tight", pil_kwargs=PNG)
    return path
