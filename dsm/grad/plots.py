"""dsm grad's report figures, drawn from its CSV files' rows (dicts of strings) after the measuring.

``relative_error.png``: each technique's (and projective integrator's) relative error against the
truth, a dot per parameter; ``inverse.png``: the inverse task's final error per start, a line per
technique, a panel per parameter. As the report's figures (dsm.report.figures): matplotlib's Agg
canvas without pyplot, drawn at DPI and shown at pixel size (MIN_FONT text reads at 9 points),
Okabe & Ito's colours times markers (figures.style), symlog axes so that 0 shows.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..report.csv_table import as_number
from ..report.figures import DPI, LABEL_FONT, LINTHRESH, MIN_FONT, PNG, RC, style
from ..report.io import save_png
from .findings import by

REL_LINTHRESH = 0.01       # relative error: linear below 1 %, so 0 shows beside 1 % and 100 %
UNDEFINED_GREY = "#555555"


def _percent(x, _pos=None) -> str:
    return f"{100.0 * x:g} %"


def _save(fig, path: Path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    # tight: the legends sit right of their panels, outside the axes' layout
    save_png(path, lambda f, fmt: fig.savefig(f, dpi=DPI, format=fmt, bbox_inches="tight", pil_kwargs=PNG))


def error_rows(compare_rows, projective_rows) -> tuple:
    """(row labels top to bottom, parameters, {(label, param): relative error or None}) of the figure."""
    labels, params, err = [], [], {}
    for r in compare_rows:
        labels += [r["technique"]] if r["technique"] not in labels else []
        params += [r["param"]] if r["param"] not in params else []
        err[(r["technique"], r["param"])] = as_number(r["rel_error"])
    for r in projective_rows:
        name = f"{r['integrator']} ({r['spp']} spp x {r['seeds']})"
        labels += [name] if name not in labels else []
        params += [r["param"]] if r["param"] not in params else []
        err[(name, r["param"])] = as_number(r["rel_error"])
    return labels, params, err


def relative_error_figure(path: Path, compare_rows, projective_rows=()):
    """relative_error.png: a row per technique (then integrator), a dot per parameter at its relative error;
    an undefined error (a truth of 0) is written as such at the row's right."""
    from matplotlib import rc_context
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter
    labels, params, err = error_rows(compare_rows, projective_rows)
    top = max([v for v in err.values() if v is not None] + [1.0])
    with rc_context(RC):
        fig = Figure(figsize=(6.4, 0.9 + 0.24 * len(labels)))
        ax = fig.add_subplot()
        for k, p in enumerate(params):
            st = style(k)
            pts = [(err[(n, p)], i) for i, n in enumerate(labels) if err.get((n, p)) is not None]
            ax.plot([x for x, _ in pts], [y for _, y in pts], ls="none", marker=st["marker"], ms=5,
                    color=st["color"], label=p, alpha=0.9)
        for i, n in enumerate(labels):
            missing = [p for p in params if (n, p) in err and err[(n, p)] is None]
            if missing:
                ax.annotate("undefined: " + ", ".join(missing), (1.0, i), xycoords=("axes fraction", "data"),
                            xytext=(-3, 0), textcoords="offset points", ha="right", va="center",
                            fontsize=MIN_FONT, color=UNDEFINED_GREY)
        ax.set_yticks(range(len(labels)), labels, fontsize=MIN_FONT)
        ax.set_ylim(len(labels) - 0.5, -0.5)
        ax.set_xscale("symlog", linthresh=REL_LINTHRESH, linscale=0.5)
        ax.set_xlim(0, 10 ** math.ceil(math.log10(top * 1.5)))
        ax.xaxis.set_major_formatter(FuncFormatter(_percent))
        ax.grid(axis="x", color="#dddddd", lw=0.6)
        ax.set_xlabel("relative error of the loss's derivative, |AD - truth| / |truth| (linear below 1 %)",
                      fontsize=LABEL_FONT)
        ax.legend(title="parameter", fontsize=MIN_FONT, title_fontsize=MIN_FONT, loc="upper left",
                  bbox_to_anchor=(1.01, 1.0), frameon=False)
    _save(fig, path)


def inverse_figure(path: Path, inverse_rows, tolerance: float | None = None):
    """inverse.png: a panel per parameter, the final error (symlog) against the start offset, a line per
    technique, the success tolerance dashed (where known)."""
    from matplotlib import rc_context
    from matplotlib.figure import Figure
    groups = by(inverse_rows, "param")
    techs = list(by(inverse_rows, "technique"))
    top = max([as_number(r["final_error"]) or 0.0 for r in inverse_rows] + [tolerance or 0.0, LINTHRESH])
    with rc_context(RC):
        fig = Figure(figsize=(3.3 * len(groups) + 1.6, 3.0))
        axes = fig.subplots(1, len(groups), squeeze=False)[0]
        for ax, (param, rs) in zip(axes, groups.items()):
            for k, t in enumerate(techs):
                pts = sorted((x, y) for x, y in ((as_number(r["start_offset"]), as_number(r["final_error"]))
                                                 for r in rs if r["technique"] == t) if x is not None and y is not None)
                st = style(k)
                ax.plot([x for x, _ in pts], [y for _, y in pts], marker=st["marker"], ls=st["ls"], ms=4, lw=1.0,
                        color=st["color"], label=t)
            if tolerance is not None:
                ax.axhline(tolerance, color="k", ls="--", lw=1.4, label="tolerance (success below)")
            ax.set_yscale("symlog", linthresh=LINTHRESH, linscale=0.6)
            ax.set_ylim(0, 10 ** math.ceil(math.log10(top * 1.5)))
            unit = rs[0].get("unit", "")
            ax.set_title(param, fontsize=LABEL_FONT)
            ax.set_xlabel(f"start offset from the truth ({unit})", fontsize=LABEL_FONT)
            ax.set_ylabel(f"final error ({unit})", fontsize=LABEL_FONT)
            ax.grid(color="#eeeeee", lw=0.6)
        axes[-1].legend(fontsize=MIN_FONT, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False,
                        handlelength=3)
        fig.subplots_adjust(wspace=0.35)
    _save(fig, path)
