"""A section's markdown file: its cells as the report writes numbers, its table written atomically."""
from __future__ import annotations

from .. import io as report
from ...truth import metrics


def cell(x) -> str:
    """A table cell: a float to 4 significant digits, '-' where it is undefined, anything else as text."""
    if isinstance(x, float):
        return "-" if not metrics.defined(x) else f"{x:.4g}"
    return str(x)


def write_table(path, title: str, intro: str, columns: list, rows: list):
    """``path`` as '# title', the intro and one row per ``rows`` entry under ``columns`` (key, heading)."""
    lines = [f"# {title}", "", intro, "", "| " + " | ".join(h for _, h in columns) + " |", "|---" * len(columns) + "|"]
    lines += ["| " + " | ".join(cell(r.get(k, "")) for k, _ in columns) + " |" for r in rows]
    with report.atomic(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
