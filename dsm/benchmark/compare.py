"""Two benchmark results compared: which cases changed, under a stated rule for what counts as a change.

Counts from two machines differ by float32 rounding (about 0.1 % of receivers, measured CPU
against GPU). The rule: a case's count (receivers, acne, peter-panning) has changed when it moved
by more than ``max(0.1 % of A's receivers, 2)`` receivers; a smaller move is a tie. A case present
in one file only is added or removed. A change in the suite's hash makes the files incomparable
(they measure different suites): that is reported first, then other dsm, Mitsuba or Dr.Jit versions
(results differ bit for bit between releases), in one line.

A case's FLIP (its mean over the render's pixels, in [0, 1]) has changed when it moved by more than
``FLIP_TIE`` (0.001: a tenth of a percent of FLIP's range; a handful of pixels changing class moves it
less). A flicker record (per scene, unit, offset, light and contender) has changed when its flicker_rate
moved by more than ``FLICKER_TIE`` (0.002: 4 of the suite's 2000 fixed points over a pair's eligible
points).
"""
from __future__ import annotations

import json
from pathlib import Path

from ..core import env
from .ranking import offset_of

COUNTS = ("n_receivers", "n_acne", "n_peterpan")
TIE_FRACTION = 0.001           # of the case's receivers
TIE_MIN = 2                    # receivers
FLIP_TIE = 0.001               # of FLIP's [0, 1]
FLICKER_TIE = 0.002            # of flicker_rate's [0, 1]


def case_key(rec: dict) -> tuple:
    """A case's identity across runs: (scene, unit, offset, light, contender); a dsm-bench-1 record,
    which has no offset, sits at the origin ("0")."""
    return rec["scene"], rec["unit"], offset_of(rec), rec["light"], rec["contender"]


def tie_tolerance(n_receivers: int) -> float:
    """The largest count move that is a tie: max(0.1 % of the receivers, 2)."""
    return max(TIE_FRACTION * n_receivers, TIE_MIN)


def case_changes(a: dict, b: dict) -> list:
    """The counts of one case that changed from ``a`` to ``b``: (count, value in a, value in b)."""
    tol = tie_tolerance(a["n_receivers"])
    moves = [(c, a[c], b[c]) for c in COUNTS if c in a and c in b and abs(b[c] - a[c]) > tol]
    return moves + _moved(a, b, "flip", FLIP_TIE)


def _moved(a: dict, b: dict, key: str, tie: float) -> list:
    """[(key, a's, b's)] where ``key`` moved by more than ``tie``, or became undefined (NaN) or
    defined: a value that is lost is a change, not a tie; both undefined are alike."""
    x, y = a.get(key), b.get(key)
    if x is None or y is None or (x != x and y != y):
        return []
    if x != x or y != y:
        return [(key, x, y)]
    return [(key, x, y)] if abs(y - x) > tie else []


def flicker_changes(doc_a: dict, doc_b: dict) -> dict:
    """The flicker records that changed (flicker_rate beyond FLICKER_TIE), tied, added and removed."""
    a = {case_key(r): r for r in doc_a.get("flicker", [])}
    b = {case_key(r): r for r in doc_b.get("flicker", [])}
    changed = [{"case": list(k), "moves": [list(m) for m in _moved(a[k], b[k], "flicker_rate", FLICKER_TIE)]}
               for k in sorted(set(a) & set(b))]
    changed = [c for c in changed if c["moves"]]
    return {"changed": changed, "n_tied": len(set(a) & set(b)) - len(changed),
            "added": [list(k) for k in sorted(set(b) - set(a))], "removed": [list(k) for k in sorted(set(a) - set(b))]}


def compare(doc_a: dict, doc_b: dict) -> dict:
    """What changed from result ``doc_a`` to ``doc_b``: changed, tied, added and removed cases."""
    a = {case_key(r): r for r in doc_a["cases"] if "n_acne" in r}
    b = {case_key(r): r for r in doc_b["cases"] if "n_acne" in r}
    changed, tied = [], 0
    for k in sorted(set(a) & set(b)):
        moves = case_changes(a[k], b[k])
        if moves:
            changed.append({"case": list(k), "moves": [list(m) for m in moves]})
        else:
            tied += 1
    return {"same_suite": doc_a.get("suite_sha256") == doc_b.get("suite_sha256"),
            "suites": [doc_a.get("suite"), doc_b.get("suite")],
            "commits": [doc_a.get("versions", {}).get("dsm_git_commit"), doc_b.get("versions", {}).get("dsm_git_commit")],
            "versions": [env.engine(doc_a.get("versions")), env.engine(doc_b.get("versions"))],
            "versions_change": env.engine_change(doc_a.get("versions"), doc_b.get("versions")),
            "rule": f"a count is changed when it moves by more than max({TIE_FRACTION:.1%} of A's receivers, "
                    f"{TIE_MIN}), FLIP by more than {FLIP_TIE:g}, a flicker rate by more than {FLICKER_TIE:g}; else a tie",
            "changed": changed, "n_tied": tied, "flicker": flicker_changes(doc_a, doc_b),
            "added": [list(k) for k in sorted(set(b) - set(a))], "removed": [list(k) for k in sorted(set(a) - set(b))]}


def text(diff: dict) -> str:
    """The comparison as printed lines."""
    lines = [f"suites {diff['suites'][0]} -> {diff['suites'][1]}" + ("" if diff["same_suite"] else
             " (different suite hashes: the files measure different suites)"),
             *([f"versions differ: {diff['versions_change']} (results differ bit for bit between versions: a "
                 "change may be theirs)"] if diff.get("versions_change") else []),
             f"rule: {diff['rule']}",
             f"{len(diff['changed'])} cases changed, {diff['n_tied']} tied, {len(diff['added'])} added, "
             f"{len(diff['removed'])} removed"]
    for c in diff["changed"]:
        moves = ", ".join(f"{n} {x} -> {y}" for n, x, y in c["moves"])
        lines.append(f"  changed {'/'.join(c['case'])}: {moves}")
    lines += [f"  added {'/'.join(k)}" for k in diff["added"]] + [f"  removed {'/'.join(k)}" for k in diff["removed"]]
    fl = diff.get("flicker", {"changed": [], "n_tied": 0, "added": [], "removed": []})
    lines.append(f"flicker: {len(fl['changed'])} records changed, {fl['n_tied']} tied, {len(fl['added'])} added, "
                 f"{len(fl['removed'])} removed")
    for c in fl["changed"]:
        lines.append(f"  changed {'/'.join(c['case'])}: " + ", ".join(f"{n} {x:.4g} -> {y:.4g}" for n, x, y in c["moves"]))
    return "\n".join(lines)


def write(diff: dict, out: Path) -> Path:
    """Write ``compare.json`` and ``compare.txt`` in ``out``; returns the JSON's path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.txt").write_text(text(diff) + "\n")
    path = out / "compare.json"
    path.write_text(json.dumps(diff, indent=1))
    return path
