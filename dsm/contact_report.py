"""table.md's contact-shadow section: per scheme instance and per case, the error before and after
the march, what it recovers, what it darkens wrongly and what it misses (dsm.contact)."""
from __future__ import annotations

import numpy as np

from . import metrics, summary

# images/<scene>_<light>/<case>_contact.png: what the march did per receiver
CONTACT_CLASSES = ("not a receiver", "lit, right", "shadowed, right", "recovered (peter-pan the march shadows)",
                   "false shadow (lit, the march shadows)", "missed (peter-pan left)", "acne (the map's)")
CONTACT_COLORS = np.array([[0, 0, 0], [205, 205, 205], [90, 90, 90], [40, 170, 60], [220, 40, 40],
                           [245, 150, 20], [150, 60, 200]], np.uint8)


def classes(v, v_star, occluded) -> np.ndarray:
    """Per receiver its index in CONTACT_CLASSES (1 to 6) after the march."""
    lit_map = np.asarray(v, float) >= 0.5
    gt, occ = np.asarray(v_star, bool), np.asarray(occluded, bool)
    out = np.where(gt, np.where(lit_map, 1, 6), np.where(lit_map, 5, 2)).astype(np.uint8)
    out[gt & lit_map & occ] = 4
    out[~gt & lit_map & occ] = 3
    return out


def write_image(path, pixels, cls, width: int, height: int):
    """The contact image of one case: each receiver's class colour (black: not a receiver)."""
    from PIL import Image
    from .report import atomic
    img = np.zeros(width * height, np.uint8)
    img[pixels] = cls
    with atomic(path) as tmp:
        Image.fromarray(CONTACT_COLORS[img.reshape(height, width)]).save(tmp, format="png")


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
