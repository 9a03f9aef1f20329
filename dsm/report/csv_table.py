"""Any CSV the kit writes as a sortable HTML table: numbers to their meaningful digits
(labels.number_text), the exact text as the CSV holds it in the cell's value (sorting) and on hover,
and an empty cell (the kit's undefined) as the word ``undefined``, sorted last.

A page shows such a table with the templates' table macro (dsm.report.templates) and sort.js: a
click on a header sorts by that column (numbers by value, text alphabetically).
"""
from __future__ import annotations

import math

from ..core import labels
from .templates import Cell, Row, Table

UNDEFINED = "undefined"


def as_number(cell) -> float | None:
    """A CSV cell as a finite float (None for a missing or empty cell, text, a boolean's True / False,
    or nan and inf: no measured value, undefined)."""
    if cell in (None, "", "True", "False"):
        return None
    try:
        x = float(cell)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def _parses(cell: str) -> bool:
    """Whether a cell reads as a float (nan and inf included: the column still sorts as numbers)."""
    try:
        float(cell)
    except (TypeError, ValueError):
        return False
    return cell not in ("True", "False")


def numeric_columns(columns, rows) -> set:
    """The columns whose every non-empty cell is a number (at least one cell holding one)."""
    out = set()
    for c in columns:
        cells = [r.get(c) or "" for r in rows]
        filled = [x for x in cells if x != ""]
        if filled and all(_parses(x) for x in filled):
            out.add(c)
    return out


def shown(cell: str, numeric: bool) -> str:
    """A cell as read: ``undefined`` when empty, a number to labels.DIGITS significant digits (an
    integer as written)."""
    if cell == "":
        return UNDEFINED
    if not numeric or cell.lstrip("-").isdigit():
        return cell
    x = float(cell)
    return labels.number_text(x) if math.isfinite(x) else cell


def cell(text: str, numeric: bool) -> Cell:
    """One cell: the shown text; its exact CSV text as data-v (what the sort reads) and, where it is
    shown otherwise, on hover."""
    text_shown = shown(text, numeric)
    return Cell(text_shown, text, numeric, f"exact: {text}" if text and text_shown != text else None)


TALL = 25                 # rows: a longer table scrolls in a box of report.html's height (.scroll)


def table(columns, rows, table_id: str) -> Table:
    """A sortable table of a CSV's ``rows`` (dicts of strings, as csv.DictReader reads them) in
    ``columns``' order, in a box that scrolls sideways where it is wider than the page (and down
    where it has more than TALL rows)."""
    num = numeric_columns(columns, rows)
    body = [Row([cell(r.get(c) or "", c in num) for c in columns]) for r in rows]
    return Table([(c, "num" if c in num else "text") for c in columns], body, table_id, ("sortable",),
                 "wide scroll" if len(rows) > TALL else "wide")
