"""The run's files: atomic writes, metrics.csv row by row, whole CSV and JSON files, typed reading."""
from __future__ import annotations

import contextlib
import csv
import json
import os
from pathlib import Path

from ..core import record
from ..truth import metrics

COLUMNS = record.NAMES          # metrics.csv's columns: the run record's schema (dsm.core.record)
TEXT_COLUMNS = record.TEXT_COLUMNS
INT_COLUMNS = record.INT_COLUMNS


@contextlib.contextmanager
def atomic(path: Path):
    """Yield a temporary path beside ``path``; rename it to ``path`` once written, so a reader
    (or an interrupted run) never sees a half-written file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_csv(path: Path, columns: list, rows: list, exact=()):
    """A whole CSV file of ``rows`` in ``columns`` at once, atomically (undefined: empty cells).
    Columns in ``exact`` are written so they read back to the same float (a value a user
    pastes back, such as an oracle's bias); the others to 6 significant digits."""
    with atomic(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([_exact(r.get(c, "")) if c in exact else _fmt(r.get(c, "")) for c in columns])


def _exact(x):
    return repr(float(x)) if isinstance(x, float) and metrics.defined(x) else _fmt(x)


def write_text(path: Path, text: str):
    """Write ``text`` (UTF-8) into ``path`` atomically."""
    with atomic(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path: Path, data: dict, indent=None):
    """Write ``data`` as JSON into ``path`` atomically (values JSON cannot hold as their ``str``)."""
    with atomic(path) as tmp:
        tmp.write_text(json.dumps(data, indent=indent, default=str))


def save_png(path: Path, save):
    """``save(file_object_or_path, format)`` into ``path`` atomically."""
    with atomic(path) as tmp:
        save(tmp, "png")


class CsvWriter:
    """Appends one row per finished case, flushing each, so a crash loses nothing done."""

    def __init__(self, path: Path):
        self.path = path
        with open(path, "w", newline="") as fh:
            csv.writer(fh).writerow(COLUMNS)

    def write(self, row: dict):
        """Append ``row``, refusing one that does not fit the schema (record.check_row)."""
        record.check_row(row)
        with open(self.path, "a", newline="") as fh:
            csv.writer(fh).writerow([_fmt(row.get(c, "")) for c in COLUMNS])


def _fmt(x):
    if isinstance(x, float):
        return f"{x:.6g}" if metrics.defined(x) else ""      # undefined: an empty cell
    return x


def whole_rows(rows: list) -> list:
    """The rows of a read CSV that are whole: a row cut short (a run killed while writing it) has
    missing cells (None values) or extra ones (a None key)."""
    return [r for r in rows if None not in r and None not in r.values()]


def read_csv(path) -> list[dict]:
    """The rows of the CSV file ``path`` as dicts of strings."""
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _typed(k, v):
    if k in TEXT_COLUMNS:
        return v
    if v == "":
        return metrics.UNDEFINED
    if k in INT_COLUMNS or k.startswith("n_") or "_n_" in k:
        return int(v)
    return float(v)


def read_rows(path) -> list[dict]:
    """metrics.csv or oracle.csv with its numbers as int and float (an empty cell: NaN): the rows
    every report section is written from, in a run and in ``dsm report``."""
    return typed_rows(read_csv(path))


def typed_rows(raw: list) -> list[dict]:
    """Rows read as text (csv.DictReader) with their numbers as int and float ('' is NaN)."""
    return [{k: _typed(k, v) for k, v in r.items()} for r in raw]
