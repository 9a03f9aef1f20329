"""Any CSV the kit writes as a sortable HTML table: numbers to their meaningful digits
(labels.number_text), the exact text as the CSV holds it in the cell's value (sorting) and on hover,
and an empty cell (the kit's undefined) as the word ``undefined``, sorted last.

A page that shows such tables adds report.html's style (html.CSS) and SORT_SCRIPT: a click on a
header sorts by that column (numbers by value, text alphabetically).
"""
from __future__ import annotations

import html
import math

from . import labels
from .html import SCRIPT

SORT_SCRIPT = SCRIPT.split("const cases")[0]      # report.html's header sort, without its case viewer
UNDEFINED = "undefined"


def _e(x) -> str:
    return html.escape(str(x), quote=True)


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


def cell_html(cell: str, numeric: bool) -> str:
    """One <td>: the shown text; its exact CSV text as data-v (what the sort reads) and, where it is
    shown otherwise, on hover."""
    text = shown(cell, numeric)
    title = f' title="exact: {_e(cell)}"' if cell and text != cell else ""
    return f"<td{' class=n' if numeric else ''} data-v=\"{_e(cell)}\"{title}>{_e(text)}</td>"


TALL = 25                 # rows: a longer table scrolls in a box of report.html's height (.scroll)


def table_html(columns, rows, table_id: str) -> str:
    """A sortable table of a CSV's ``rows`` (dicts of strings, as csv.DictReader reads them) in
    ``columns``' order, in a box that scrolls sideways where it is wider than the page (and down
    where it has more than TALL rows)."""
    num = numeric_columns(columns, rows)
    head = "".join(f"<th data-type={'num' if c in num else 'text'}>{_e(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(cell_html(r.get(c) or "", c in num) for c in columns) + "</tr>" for r in rows)
    box = "wide scroll" if len(rows) > TALL else "wide"
    return (f"<div class=\"{box}\"><table id=\"{_e(table_id)}\" class=sortable><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table></div>")
