"""A run's results as a notebook or test reads them: the rows, run.json and the class images."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..report import tables as report
from ..truth import metrics


@dataclass
class Results:
    """What a run produced: the rows of metrics.csv, run.json's content and the images."""
    out: Path
    rows: list
    run: dict
    images: dict = field(default_factory=dict)   # case id -> class image (H, W) uint8
    oracle: list = field(default_factory=list)   # the rows of oracle.csv (per map, format and lambda)
    curves: list = field(default_factory=list)   # per map and format: (row, world Curve, texel Curve)

    def where(self, **kw) -> "Results":
        """The results whose rows have every given column at the given value."""
        unknown = sorted(set(kw) - set(report.COLUMNS))
        if unknown:
            raise KeyError(f"Results.where: no column {', '.join(unknown)} (columns: see dsm.core.record.NAMES, "
                           "e.g. scheme, params, scene, light, view, resolution, filter, format)")
        rows = [r for r in self.rows if all(r.get(k) == v for k, v in kw.items())]
        return Results(self.out, rows, self.run, {r["case"]: self.images.get(r["case"]) for r in rows},
                       self.oracle, self.curves)

    def column(self, name) -> np.ndarray:
        """The values of column ``name`` over the rows, as a numpy array (a KeyError names the columns)."""
        if name not in report.COLUMNS:
            raise KeyError(f"Results.column: no column {name!r} (columns: see dsm.core.record.NAMES, e.g. acne_rate, "
                           "peterpan_rate, error_rate, n_receivers)")
        return np.array([r[name] for r in self.rows])

    def rgb(self, case) -> np.ndarray:
        """The case's error image as (H, W, 3) uint8 in the report's colours."""
        if isinstance(case, dict):
            case = case["case"]
        if case not in self.images or self.images[case] is None:
            ids = sorted(k for k, v in self.images.items() if v is not None)
            raise KeyError(f"Results.rgb: no image of case {case!r} (cases are ids like {ids[0]!r} to {ids[-1]!r}, "
                           "or rows)" if ids else f"Results.rgb: no image of case {case!r}: this run kept no images")
        return metrics.CLASS_COLORS[self.images[case]]

    def table(self, columns=("scheme", "params", "resolution", "acne_rate", "peterpan_rate", "error_rate",
                             "build_ms", "lookup_ms")) -> str:
        """The rows as a Markdown table of the chosen columns (for notebooks and terminals)."""
        fmt = lambda v: f"{v:.4f}" if isinstance(v, float) and abs(v) < 10 else (f"{v:.1f}" if isinstance(v, float) else str(v))
        lines = ["| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]
        lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |" for r in self.rows]
        return "\n".join(lines)

    def _repr_markdown_(self):
        return self.table()

    def __getattr__(self, name):
        if name in report.COLUMNS:
            return self.column(name)
        raise AttributeError(name)

    def __len__(self):
        return len(self.rows)
