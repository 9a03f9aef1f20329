"""The table of experiments/contact_bias.toml from its run folder: per scheme and resolution, the
largest bias whose pooled error stays within 1.1x the sweep's minimum, without and with contact
shadows, then the pooled error at each bias.

    python scripts/contact_bias.py runs/contact_bias-<time>/

Pooled error over a (scheme, resolution, bias) group: (acne + peter-pan) summed over its cases
(the scenes) / receivers summed; with contact: the same after the march (contact_error_rate's
counts). The sweep's minimum is each column's own (without, with).
"""
from __future__ import annotations

import sys
from pathlib import Path

from dsm.report.sections import contact as contact_report
from dsm.report import io as report
from dsm.experiment import resume

TOLERANCE = 1.1


def groups(rows: list) -> dict:
    """(scheme, resolution) -> {bias value: (pooled error, pooled error with contact)}."""
    out = {}
    for r in rows:
        key = (r["scheme"], r["resolution"])
        out.setdefault(key, {}).setdefault(r["sweep_value"], []).append(r)
    return {k: {b: (lambda p: (p["error"], p["contact_error"]))(contact_report.pooled(rs)) for b, rs in v.items()}
            for k, v in out.items()}


def largest_within(errors: dict, col: int, tolerance: float = TOLERANCE):
    """The largest bias whose pooled error (column ``col``) is within ``tolerance`` x the sweep's minimum."""
    best = min(e[col] for e in errors.values())
    return max(b for b, e in errors.items() if e[col] <= tolerance * best), best


def bias_label(value, rows, scheme) -> str:
    """A sweep value as the config wrote it (its unit: the params column's)."""
    for r in rows:
        if r["scheme"] == scheme and r["sweep_value"] == value:
            return r["params"].split()[0].split("=", 1)[1]
    return f"{value:g}"


def table(rows: list) -> str:
    """The two Markdown tables (largest bias; pooled error at each bias)."""
    g = groups(rows)
    lines = [f"| scheme | R | largest bias without | (min error) | largest bias with contact | (min error) |",
             "|---|---|---|---|---|---|"]
    for (scheme, R), errs in sorted(g.items()):
        (b0, m0), (b1, m1) = largest_within(errs, 0), largest_within(errs, 1)
        lines.append(f"| {scheme} | {R} | {bias_label(b0, rows, scheme)} | {m0:.4f} | {bias_label(b1, rows, scheme)} "
                     f"| {m1:.4f} |")
    lines += ["", "| scheme | R | bias | error | error with contact |", "|---|---|---|---|---|"]
    for (scheme, R), errs in sorted(g.items()):
        for b, (e0, e1) in sorted(errs.items()):
            lines.append(f"| {scheme} | {R} | {bias_label(b, rows, scheme)} | {e0:.4f} | {e1:.4f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    folder = Path(sys.argv[1])
    rows = [resume.parse_row(r) for r in report.read_csv(folder / "metrics.csv")]
    print(table(contact_report.contact_rows(rows)))
