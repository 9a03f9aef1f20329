"""The kit's HTML pages from one set of Jinja2 templates (this folder): report.html (dsm.report.html),
leaderboard.html (dsm.benchmark.page), a contender's page (dsm.benchmark.contenders) and dsm grad's
report.html (dsm.grad.page).

Each page's template extends base.html (the head, the shared style, the header, a ``first_screen``
block) and draws its tables, figures and legends with macros.html. The page modules hand it values:
words and numbers as text (escaped here: autoescape), tables as ``Table`` of ``Row`` of ``Cell``. A
page's scripts and report.css are static files of this folder placed inside the page (``inline``), so
each page opens from the file system as one file, with no server and no network. A variable the
template names and the page does not give fails (StrictUndefined) rather than print nothing.
"""
from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import NamedTuple

import jinja2
from markupsafe import Markup, escape

from ...truth import metrics

HERE = Path(__file__).parent


class Cell(NamedTuple):
    """A table cell: its text; ``value`` its data-v (what a sort reads; None: none); ``num`` right-aligned;
    ``title`` its hover; ``href`` a link around the text."""
    text: object
    value: object = None
    num: bool = False
    title: str | None = None
    href: str | None = None


class Row(NamedTuple):
    """A table row: its cells, its data attributes (what the filters and scripts read), an id and a class."""
    cells: list
    data: dict = {}          # never written to: every row without attributes shares it
    id: str | None = None
    cls: str | None = None


class Table(NamedTuple):
    """A table: ``columns`` (title, data-type or None), its rows, an id, its classes, the class of a box
    around it (None: no box)."""
    columns: list
    rows: list
    id: str | None = None
    classes: tuple = ()
    box: str | None = None


@cache
def inline(name: str) -> Markup:
    """A static file of this folder (a script, a style sheet), to be placed inside a page as it is."""
    return Markup((HERE / name).read_text(encoding="utf-8"))


def class_colours() -> list:
    """(name, CSS colour) of each error class (metrics.CLASS_COLORS: the case images' colours)."""
    return [(n, f"rgb{tuple(int(c) for c in col)}") for n, col in zip(metrics.CLASS_NAMES, metrics.CLASS_COLORS)]


def cell_html(c: Cell) -> str:
    """A cell's ``<td>`` (numbers class n, data-v the value a sort reads, title its hover, href a link),
    its text and values escaped as the templates escape a value."""
    head = "<td class=n" if c.num else "<td"
    if c.value is not None:
        head += f' data-v="{escape(c.value)}"'
    if c.title is not None:
        head += f' title="{escape(c.title)}"'
    if c.href is not None:
        return f'{head}><a href="{escape(c.href)}">{escape(c.text)}</a></td>'
    return f"{head}>{escape(c.text)}</td>"


def row_html(r: Row) -> str:
    """A row's ``<tr>``: its id, class and data attributes, then its cells."""
    head = "<tr"
    if r.id:
        head += f" id={escape(r.id)}"
    if r.cls:
        head += f" class={escape(r.cls)}"
    for k, v in r.data.items():
        head += f' data-{escape(k)}="{escape(v)}"'
    return head + ">" + "".join(cell_html(c) for c in r.cells) + "</tr>"


def table_rows(rows) -> Markup:
    """A table's body rows, a line each: the pages' largest part (a report's case table has a row per case),
    written here rather than by a macro per row and cell (Jinja's macro calls were most of a page's time)."""
    return Markup("".join(row_html(r) + "\n" for r in rows))


@cache
def environment() -> jinja2.Environment:
    """The templates' environment: autoescape on, a missing variable an error, block tags on their own
    lines leave no blank lines."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(HERE), autoescape=jinja2.select_autoescape(["html"]),
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.globals.update(inline=inline, CLASSES=class_colours(), table_rows=table_rows)
    env.filters["capitalize_first"] = lambda text: text[:1].upper() + text[1:]    # the rest as written (labels)
    return env


def render(name: str, **context) -> str:
    """The template ``name`` of this folder rendered with ``context``."""
    return environment().get_template(name).render(**context)
