"""The answer in words at the top of dsm grad's report.html, computed from its CSV files' rows.

Rows are dicts of strings as csv.DictReader reads them (an empty cell: undefined). Per parameter,
the technique closest to a truth is the one with the smallest error; several with the same
smallest value are a tie and named together; a parameter whose every error is undefined is said
to be undefined, never given a winner.
"""
from __future__ import annotations

from ..report.csv_table import as_number
from ..core.labels import number_text
from .equal_error import BELOW, DISAGREES, NEVER, REACHED, UNDEFINED

# why a time ratio is undefined, by equal_error.csv's status
UNDEFINED_WHY = {UNDEFINED: "the technique's relative error is undefined: the truth over the pixels the integrator "
                            "sees is 0",
                 NEVER: "path tracing never reached its error within the spp range",
                 DISAGREES: "the integrator disagrees with the truth",
                 REACHED: "path tracing's time there is undefined",
                 BELOW: "path tracing's time is undefined"}



def pct(x: float | None) -> str:
    """A fraction as a percentage to 3 significant digits ('undefined' for None)."""
    return "undefined" if x is None else f"{number_text(100.0 * x, 3)} %"


def count(n: int, noun: str) -> str:
    """'1 row', '2 rows', '0 rows'."""
    return f"{n} {noun}" + ("" if n == 1 else "s")


def names(xs: list) -> str:
    """'a', 'a and b', 'a, b and c'."""
    return xs[0] if len(xs) == 1 else ", ".join(xs[:-1]) + " and " + xs[-1]


def by(rows, key: str) -> dict:
    """Rows grouped by a column's value, in the CSV's order."""
    out = {}
    for r in rows:
        out.setdefault(r[key], []).append(r)
    return out


def smallest(rows, value: str, name: str = "technique") -> tuple:
    """(names with the smallest defined ``value``, that value), or ([], None) when every value is undefined."""
    vals = [(r[name], as_number(r.get(value, ""))) for r in rows]
    vals = [(n, v) for n, v in vals if v is not None]
    if not vals:
        return [], None
    best = min(v for _, v in vals)
    return [n for n, v in vals if v == best], best


def winner_phrase(who: list, value, what: str, why: str) -> str:
    """'a (x %)', 'a tie between a and b (x % each)', or 'undefined (every <what> is undefined: <why>)'."""
    if not who:
        return f"undefined (every {what} is undefined: {why})"
    if len(who) == 1:
        return f"{who[0]} ({pct(value)})"
    return f"a tie between {names(who)} ({pct(value)} each)"


def closest_to_truth(rows) -> tuple:
    """(techniques, their relative errors) closest to the truth among compare.csv rows of one parameter: the
    smallest |ad - reference| and every one within twice the truth's own error of it (the truth's error
    cannot order them: a tie); ([], []) where every relative error is undefined (the truth is 0)."""
    cand = [(abs(as_number(r["ad"]) - as_number(r["reference"])), as_number(r["reference_error"]) or 0.0,
             as_number(r["rel_error"]), r["technique"]) for r in rows
            if None not in (as_number(r["rel_error"]), as_number(r["ad"]), as_number(r["reference"]))]
    if not cand:
        return [], []
    dev, err, _, _ = min(cand)
    near = [c for c in cand if c[0] - dev <= 2.0 * max(err, c[1])]
    return [c[3] for c in near], [c[2] for c in near]


def compare_words(rows) -> str:
    """compare.csv: per parameter, the technique whose gradient is closest to the truth (relative error), or
    the techniques the truth's own error cannot tell apart."""
    parts = []
    for param, rs in by(rows, "param").items():
        who, rel = closest_to_truth(rs)
        if not who:
            zero = all(as_number(r["reference"]) == 0.0 for r in rs)
            within = all(None not in (ref := as_number(r["reference"]), err := as_number(r["reference_error"]))
                         and abs(ref) <= err for r in rs)
            why = ("the truth is 0" if zero else "the truth is 0 within its own error" if within
                   else "the truth is 0 or undefined")
            phrase = winner_phrase([], None, "relative error", why)
        elif len(who) == 1:
            r = next(r for r in rs if r["technique"] == who[0])
            cos = as_number(r.get("cosine", ""))
            phrase = (f"{who[0]} ({pct(rel[0])}), sign {r.get('sign') or 'undefined'}, per-pixel cosine "
                      f"{'undefined' if cos is None else number_text(cos, 3)}")
        elif min(rel) == max(rel):
            phrase = f"a tie between {names(who)} ({pct(rel[0])} each)"
        else:
            phrase = (f"a tie within the truth's own error between {names(who)} "
                      f"({pct(min(rel))} to {pct(max(rel))})")
        parts.append(f"{param}: {phrase}")
    return "Closest to the truth (relative error of the loss's derivative), per parameter: " + "; ".join(parts) + "."


def measured_nothing(r) -> bool:
    """Whether a projective.csv row's truth over the pixels it sees is exactly 0 with no error of its own: the
    mask hid the whole shadow, so its agreement (0 against 0) says nothing."""
    return as_number(r.get("reference")) == 0.0 and as_number(r.get("reference_error")) == 0.0


def projective_words(rows) -> str:
    """projective.csv: which of Mitsuba's projective integrators agreed with the truth (a truth of 0 over the
    pixels it sees, measuring nothing, said apart)."""
    label = lambda r: f"{r['integrator']} on {r['param']}"
    blind = [label(r) for r in rows if measured_nothing(r)]
    rest = [r for r in rows if not measured_nothing(r)]
    agree = [label(r) for r in rest if r["agrees"] == "True"]
    disagree = [f"{label(r)} (relative error {pct(as_number(r['rel_error']))})" for r in rest if r["agrees"] != "True"]
    head = f"Mitsuba's projective integrators agreed with the truth in {len(agree)} of {count(len(rows), 'case')}"
    tail = (f": {names(agree)}" if agree else "") + (f"; disagreed (a finding): {names(disagree)}" if disagree else "")
    none = (f"; measured nothing (the truth over the pixels it sees is 0: the mask hides the whole shadow): "
            f"{names(blind)}" if blind else "")
    return head + tail + none + "."


def success(rows) -> tuple:
    """(successes, runs) of inverse.csv rows."""
    return sum(r["success"] == "True" for r in rows), len(rows)


def inverse_words(rows) -> str:
    """inverse.csv: per parameter, the technique(s) with the highest success rate, and the overall count."""
    parts = []
    for param, rs in by(rows, "param").items():
        rates = {t: success(g) for t, g in by(rs, "technique").items()}
        top = max(k / n for k, n in rates.values())
        who = [t for t, (k, n) in rates.items() if k / n == top]
        k, n = rates[who[0]]
        if top == 0:
            parts.append(f"{param}: no technique succeeded (0/{n} each)")
        elif len(who) == 1:
            parts.append(f"{param}: {who[0]} ({k}/{n})")
        else:
            parts.append(f"{param}: a tie between {names(who)} ({k}/{n} each)")
    k, n = success(rows)
    return (f"Inverse task: {k} of {n} descents succeeded; the highest success rate per parameter: "
            + "; ".join(parts) + ".")


def selfcheck_words(rows) -> str:
    """selfcheck.csv: per parameter, the technique closest to the closed form, and AD's largest gap to its
    own central difference."""
    parts = []
    for param, rs in by(rows, "param").items():
        if all(r["closed_form"] == "" for r in rs):
            parts.append(f"{param}: no closed form")
            continue
        who, best = smallest(rs, "ad_vs_closed")
        parts.append(f"{param}: {winner_phrase(who, best, 'gap', 'the closed form is 0')}")
    gaps = [(as_number(r["ad_vs_fd"]), r) for r in rows if as_number(r["ad_vs_fd"]) is not None]
    undefined = len(rows) - len(gaps)
    if gaps:
        worst, r = max(gaps, key=lambda g: g[0])
        rest = f"; undefined in {count(undefined, 'row')} (a central difference of 0)" if undefined else ""
        fd = f"AD against its own central difference: at most {pct(worst)} off ({r['technique']}, {r['param']}){rest}."
    else:
        fd = "AD against its own central difference: undefined in every row (every central difference is 0)."
    return "Closest to the closed form, per parameter: " + "; ".join(parts) + ". " + fd


def equal_error_words(rows) -> str | None:
    """equal_error.csv (columns technique, param, integrator, time_ratio, status): per integrator and
    parameter, the range of path tracing's time over the technique's at equal gradient error, said
    as an upper bound where path tracing's fewest samples already err less; None without those columns."""
    if not rows or not {"technique", "param", "integrator", "time_ratio", "status"} <= set(rows[0]):
        return None
    parts = []
    for (integrator, param), group in by_pair(rows).items():
        ratios = [(as_number(r["time_ratio"]), r["technique"]) for r in group if as_number(r["time_ratio"]) is not None]
        at = lambda v: names([n for x, n in ratios if x == v])
        if ratios:
            lo, hi = min(x for x, _ in ratios), max(x for x, _ in ratios)
            span = (f"{number_text(lo, 3)} ({at(lo)})" if lo == hi else
                    f"{number_text(lo, 3)} ({at(lo)}) to {number_text(hi, 3)} ({at(hi)})")
        else:
            span = "undefined for every technique"
        below = [r["technique"] for r in group if r["status"] == BELOW]
        upper = (f"; at its fewest samples it already errs less than {len(below)} of {len(group)} techniques, "
                 "so their ratios are upper bounds") if below else ""
        why = by_status([r for r in group if as_number(r["time_ratio"]) is None])
        if not ratios and len(why) == 1:
            status = next(iter(why))            # one reason for every technique: said once
            tail = f" ({UNDEFINED_WHY.get(status, status)})"
        else:
            tail = "".join(f"; undefined for {names(who)} ({UNDEFINED_WHY.get(status, status)})"
                           for status, who in why.items())
        parts.append(f"{integrator}, d/d {param}: {span}{upper}{tail}")
    return ("Cost at equal gradient error, path tracing's time over the technique's: " + "; ".join(parts) + ".")


def by_status(rows) -> dict:
    """equal_error.csv rows' technique names grouped by status, in the CSV's order."""
    out = {}
    for r in rows:
        out.setdefault(r["status"], []).append(r["technique"])
    return out


def by_pair(rows) -> dict:
    """equal_error.csv's rows grouped by (integrator, param), in the CSV's order."""
    out = {}
    for r in rows:
        out.setdefault((r["integrator"], r["param"]), []).append(r)
    return out


