"""A run's results as a notebook or test reads them: the rows, run.json and the class images."""
from __future__ import annotations

import html as htmlmod
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import record
from ..core.labels import params_label
from ..core.suggest import did_you_mean
from ..core.types import length_number
from ..report import tables as report
from ..truth import metrics


TABLE_COLUMNS = ("scheme", "params", "resolution", "acne_rate", "peterpan_rate", "error_rate", "build_ms", "lookup_ms")


def cell_text(v, column: str = "") -> str:
    """A table cell's text: a rate or time to four decimals below 10, one decimal above, ``undefined``
    for NaN (an empty denominator), ``params`` as the console and report label them, else as it is."""
    if column == "params":
        return params_label(str(v), exact=True)
    if isinstance(v, float) and v != v:
        return "undefined"
    if isinstance(v, float):
        return f"{v:.4f}" if abs(v) < 10 else f"{v:.1f}"
    return str(v)


@dataclass
class Results:
    """What a run produced: the rows of metrics.csv, run.json's content and the images."""
    out: Path
    rows: list
    run: dict
    images: dict = field(default_factory=dict)   # case id -> class image (H, W) uint8
    oracle: list = field(default_factory=list)   # the rows of oracle.csv (per map, format and lambda)
    curves: list = field(default_factory=list)   # per map and format: (row, world Curve, texel Curve)
    parent: object = field(default=None, repr=False, compare=False)   # the Results a where() came from, kept alive

    def where(self, allow_empty: bool = False, **kw) -> "Results":
        """The results whose rows have every given column at the given value, each compared by its
        column's kind (``resolution=512`` and ``"512"`` alike; a label such as ``params`` by its words
        and numbers, ``"bias=1texel"`` as ``"bias=1 texel"``). A filter that matches no row raises
        ValueError naming the values the column holds (``allow_empty=True``: an empty Results)."""
        __tracebackhide__ = True        # a test's failure shows its own line, not this method's
        named = {k for r in self.rows for k in param_values(r.get("params", ""))}
        unknown = sorted(set(kw) - set(report.COLUMNS) - named)
        if unknown:
            hint = did_you_mean(unknown[0], list(report.COLUMNS) + sorted(named))
            raise KeyError(f"Results.where: no column or scheme parameter {', '.join(unknown)} ({hint}columns: see "
                           "dsm.core.record.NAMES, e.g. scheme, params, scene, light, view, resolution, filter, "
                           f"format; the parameters of these rows: {', '.join(sorted(named)) or 'none'})")
        rows = [r for r in self.rows if all(same_value(k, row_value(r, k), v) for k, v in kw.items())]
        if not rows and not allow_empty:
            raise ValueError(no_match(self.rows, kw))
        # the parent kept alive: a run in a temporary folder keeps its folder while a part of it is in use
        return Results(self.out, rows, self.run, {r["case"]: self.images.get(r["case"]) for r in rows},
                       self.oracle, self.curves, self)

    def __repr__(self):
        name = self.run.get("experiment", "?") if isinstance(self.run, dict) else "?"
        return (f"Results({len(self.rows)} cases of {name!r} in {self.out}; columns: scheme, params, scene, light, "
                "view, resolution, filter, format, acne_rate, peterpan_rate, error_rate, ... (dsm.core.record.NAMES))")

    def to_pandas(self):
        """The rows as a pandas DataFrame in metrics.csv's column order (pandas is optional: pip install pandas)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("Results.to_pandas needs pandas, which dsm does not install: pip install pandas") from None
        return pd.DataFrame([{c: r.get(c) for c in report.COLUMNS if c in r} for r in self.rows])

    def column(self, name) -> np.ndarray:
        """The values of column ``name`` over the rows, as a numpy array (a KeyError names the columns)."""
        if name not in report.COLUMNS:
            hint = did_you_mean(name, report.COLUMNS)
            raise KeyError(f"Results.column: no column {name!r} ({hint}columns: see dsm.core.record.NAMES, e.g. acne_rate, "
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

    def table(self, columns=TABLE_COLUMNS) -> str:
        """The rows as a Markdown table of the chosen columns (for notebooks and terminals)."""
        lines = ["| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]
        lines += ["| " + " | ".join(cell_text(r.get(c, ""), c) for c in columns) + " |" for r in self.rows]
        return "\n".join(lines)

    def html(self, columns=TABLE_COLUMNS) -> str:
        """The rows as an HTML table of the chosen columns, numbers right-aligned (Jupyter and the docs site,
        whose notebook renderer shows text/html and not text/markdown)."""
        esc = lambda v, c: htmlmod.escape(cell_text(v, c))
        num = lambda v: ' style="text-align:right"' if isinstance(v, (int, float)) and not isinstance(v, bool) else ""
        head = "".join(f"<th>{htmlmod.escape(c)}</th>" for c in columns)
        body = "".join("<tr>" + "".join(f"<td{num(r.get(c))}>{esc(r.get(c, ''), c)}</td>" for c in columns) + "</tr>"
                       for r in self.rows)
        return f'<table class="dsm-results"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'

    def _repr_markdown_(self):
        return self.table()

    def _repr_html_(self):
        return self.html()

    def __getattr__(self, name):
        if name in report.COLUMNS:
            return self.column(name)
        raise AttributeError(name)

    def __len__(self):
        return len(self.rows)


_NUMBER = re.compile(r"2\^-?\d+|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def label_key(text) -> str:
    """A label compared by its words and numbers: lower case, no spaces, each number (``2^k`` too, as
    the report names a depth step) as a float to the six digits params are written with (%g)."""
    word = lambda m: repr(float(f"{length_number(m.group()):g}"))
    return _NUMBER.sub(word, str(text).replace(" ", "").lower())


def param_values(label: str) -> dict:
    """A scheme instance's parameters from its label ("bias=1 texel max=8 texel"): name -> value text
    (a unit word after a value belongs to it)."""
    out, name = {}, None
    for word in str(label).split():
        if "=" in word:
            name, _, value = word.partition("=")
            out[name] = value
        elif name is not None:
            out[name] += " " + word
    return out


def row_value(row: dict, key: str):
    """A row's column ``key``, or its scheme parameter of that name (None where it has neither)."""
    return row[key] if key in row else param_values(row.get("params", "")).get(key)


def same_value(column: str, value, wanted) -> bool:
    """Whether a row's ``value`` of ``column`` is ``wanted``, compared by the column's kind (a scheme
    parameter as a label: by its words and numbers)."""
    if value is None:
        return False
    if column in record.TEXT_COLUMNS or column not in record.NAMES:
        return value == wanted or label_key(value) == label_key(wanted)
    try:
        return value == wanted or float(value) == float(wanted)
    except (TypeError, ValueError):
        return False


def no_match(rows: list, kw: dict) -> str:
    """Why ``Results.where(**kw)`` matched nothing: the first filter no row meets alone, with the
    values its column holds; else that the filters meet no row together."""
    if not rows:        # an empty Results: no filter is to blame
        return "Results.where: the Results hold no case to select from; allow_empty=True returns the empty result"
    for k, v in kw.items():
        held = sorted({str(row_value(r, k)) for r in rows if row_value(r, k) is not None})
        if not any(same_value(k, row_value(r, k), v) for r in rows):
            shown = ", ".join(held[:12]) + (f" and {len(held) - 12} more" if len(held) > 12 else "")
            hint = did_you_mean(v, held)
            return (f"Results.where: no row has {k}={v!r} ({hint}{k} holds: {shown or 'nothing: no rows'}); "
                    "allow_empty=True returns the empty result")
    return (f"Results.where: each of {', '.join(f'{k}={v!r}' for k, v in kw.items())} matches rows, but no row "
            "matches them all; allow_empty=True returns the empty result")
