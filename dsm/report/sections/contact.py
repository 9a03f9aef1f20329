"""table.md's contact-shadow section: per scheme instance and per case, the error before and after
the march, what it recovers, what it darkens wrongly and what it misses (dsm.contact)."""
from __future__ import annotations

from ...truth import metrics
from .. import summary


def contact_rows(rows: list) -> list:
    """The rows of cases with the contact step (its columns defined)."""
    return [r for r in rows if r.get("n_contact_recovered", "") != "" and metrics.defined(r.get("n_contact_recovered"))]


def pooled(rows: list) -> dict:
    """Over ``rows``: pooled error before and after the march (errors summed over receivers summed; NaN
    without receivers) and the summed counts."""
    n = sum(r["n_receivers"] for r in rows)
    before = sum(r["n_acne"] + r["n_peterpan"] for r in rows)
    after = before - sum(r["n_contact_recovered"] for r in rows) + sum(r["n_contact_false"] for r in rows)
    return {"error": before / n if n else metrics.UNDEFINED, "contact_error": after / n if n else metrics.UNDEFINED,
            **{k: sum(r[k] for r in rows) for k in ("n_peterpan", "n_contact_recovered", "n_contact_false",
                                                    "n_contact_missed")}}


def _cell(x) -> str:
    if isinstance(x, float):
        return "-" if not metrics.defined(x) else (f"{x:.4f}" if abs(x) < 10 else f"{x:.1f}")
    return str(x)


def contact_md(rows: list) -> list:
    """The section's lines (none without contact cases): a pooled table per instance, then per case."""
    rows = contact_rows(rows)
    if not rows:
        return []
    groups = {}
    for r in rows:
        groups.setdefault(summary.instance_key(r), []).append(r)
    lines = ["", "## Contact shadows", "",
             "After each case's lookup, a march through the camera's depth buffer toward the light darkens the "
             "receivers it finds occluded ([contact], dsm.contact). Pooled error: (acne + peter-pan) summed over "
             "the cases / receivers summed, before and after; recovered: peter-panned receivers it shadows; false: "
             "truly lit receivers the map lit that it shadows; missed: peter-panned receivers left after it "
             "(casters the camera cannot see among them).", "",
             "| instance | cases | error | error with contact | peter-pan | recovered | false | missed |",
             "|---|---|---|---|---|---|---|---|"]
    for key, rs in sorted(groups.items(), key=lambda kv: pooled(kv[1])["contact_error"]):
        p = pooled(rs)
        lines.append(f"| {summary.instance_label(key)} | {len(rs)} | {_cell(p['error'])} | {_cell(p['contact_error'])} "
                     f"| {p['n_peterpan']} | {p['n_contact_recovered']} | {p['n_contact_false']} | "
                     f"{p['n_contact_missed']} |")
    cols = [("scheme", "scheme"), ("params", "params"), ("resolution", "R"), ("error_rate", "error"),
            ("contact_error_rate", "with contact"), ("n_contact_recovered", "recovered"),
            ("n_contact_false", "false"), ("n_contact_missed", "missed"), ("contact_ms", "march ms")]
    lines += ["", "| case | " + " | ".join(h for _, h in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    lines += ["| " + " | ".join([r["case"]] + [_cell(r.get(k)) for k, _ in cols]) + " |" for r in rows]
    return lines
