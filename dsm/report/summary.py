"""The answer first: per scheme instance over a run's cases, and the best instance per scene,
light and resolution (table.md's first sections, report.html's first screen, docs/results/default.md).

Definitions (stated in the report, checked by tests/test_report.py against a numpy recomputation):

- A *scheme instance* is a scheme with its parameters (or an engine preset), with the lookup
  filter, stored format and cascade layout when the run has more than one of them.
- *Pooled* rate: the errors summed over the instance's cases divided by the receivers summed
  (acne: sum n_acne / sum n_gt_lit; peter-panning: sum n_peterpan / sum n_gt_shadowed; error:
  sum (n_acne + n_peterpan) / sum n_receivers); undefined when that sum is 0.
- *Mean, median, max*: of the per-case rates where the rate is defined; the undefined ones (an
  empty denominator) are left out and counted.
- *Best in*: the number of situations (scene, light, view, resolution) where the instance's
  error rate is lower than every other instance's: an outright win (a tie is no one's win).
- *Best per scene, light and resolution*: the lowest pooled error rate over that group's cases
  (every view). Instances equal on it are one answer, a tie, named in the order of their labels;
  time never breaks a tie (a time is a measurement with noise, the counts are not).
- Every ordering here reads counts, then labels: two identical runs say the same, word for word.
- *Leak pooled* (only in a run with ``[map] kind``, whose rows carry the leak split): sum n_leak /
  sum n_gt_shadowed, a column of the first table beside peter-panning; a run without it keeps
  its table byte for byte.
"""
from __future__ import annotations

import math

import numpy as np

from ..truth.metrics import defined
from . import frontier
from ..core import labels

SITUATION = ("scene", "light", "view", "resolution")

DEFINITIONS = (
    "Per scheme instance (a scheme with its parameters, or an engine preset{extra}) over its cases: "
    "*pooled* rates are the errors summed over the cases divided by the receivers summed (acne: "
    "sum n_acne / sum n_gt_lit; peter-pan: sum n_peterpan / sum n_gt_shadowed; error: sum (n_acne + "
    "n_peterpan) / sum n_receivers); *mean / median / max* are over the per-case rates where they are "
    "defined, and *undefined* counts the cases left out (an empty denominator: no truly lit, no truly "
    "shadowed receiver, or none at all); times are means of the per-case kernel-time medians (ms); *best in*: "
    "the situations (scene, light, view, resolution) where its error rate is lower than every other "
    "instance's (a tie is no one's win). Sorted by pooled error rate, then by label.")

LEAK_COLUMN_DEFINITION = (" *Leak pooled* ([map] kind runs): sum n_leak / sum n_gt_shadowed, the false light at "
                          "least leak_texels texels inside the exact shadow (*Light leaking* below).")

BEST_DEFINITION = ("Per scene, light and resolution: the instance with the lowest pooled error rate over "
                   "that group's cases (every view), its pooled error rate in brackets. Instances equal on it "
                   "are a tie, said as one (how many, the first by label); time never breaks a tie.")
TIE_NAMES = 2          # a tie's cell names its first instances by label, then how many more


def varies(rows, key) -> bool:
    """Whether column ``key`` takes more than one value over ``rows``."""
    return len({r.get(key, "") for r in rows}) > 1


VARIED = ("filter", "format", "cascade_layout")     # part of an instance where a run varies them


def instance_key(r, multi=()) -> tuple:
    """(scheme, params or preset, then filter / format / cascade layout where the run varies them)."""
    return (r["scheme"], r["preset"] or r["params"]) + tuple(r.get(k, "") for k in multi)


def instance_label(key) -> str:
    """An instance key as words: its non-empty parts joined by spaces."""
    return " ".join(str(k) for k in key if k != "")


def _multi(rows):
    return tuple(k for k in VARIED if varies(rows, k))


def _stats(values):
    v = np.array([x for x in values if defined(x)], np.float64)
    undefined = len(values) - v.size
    if not v.size:
        return {"mean": math.nan, "median": math.nan, "max": math.nan, "undefined": undefined}
    return {"mean": float(v.mean()), "median": float(np.median(v)), "max": float(v.max()), "undefined": undefined}


def _pooled(num, den):
    return num / den if den else math.nan


def best_counts(rows, multi=None) -> dict:
    """instance key -> the number of situations where its error rate is lower than every other
    instance's (an outright win; a tie at the lowest is no one's)."""
    multi = _multi(rows) if multi is None else multi
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in SITUATION), []).append(r)
    counts = {}
    for rs in groups.values():
        scored = [r for r in rs if defined(r["error_rate"])]
        if not scored:
            continue
        low = min(r["error_rate"] for r in scored)
        winners = {instance_key(r, multi) for r in scored if r["error_rate"] == low}
        if len(winners) == 1:
            key = winners.pop()
            counts[key] = counts.get(key, 0) + 1
    return counts


def has_leak_split(rows) -> bool:
    """Whether the rows carry the leak split (a run with ``[map] kind``: its rows name a map kind)."""
    return any(r.get("map_kind") for r in rows)


def per_instance(rows) -> list:
    """One dict per scheme instance (see the module's definitions), lowest pooled error first;
    ``leak_pooled`` is NaN in a run without the leak split."""
    multi = _multi(rows)
    split = has_leak_split(rows)
    groups = {}
    for r in rows:
        groups.setdefault(instance_key(r, multi), []).append(r)
    best = best_counts(rows, multi)
    out = []
    for key, rs in groups.items():
        s = {"key": key, "scheme": key[0], "params": key[1], **dict(zip(multi, key[2:])), "cases": len(rs),
             "acne_pooled": _pooled(sum(r["n_acne"] for r in rs), sum(r["n_gt_lit"] for r in rs)),
             "peterpan_pooled": _pooled(sum(r["n_peterpan"] for r in rs), sum(r["n_gt_shadowed"] for r in rs)),
             "leak_pooled": _pooled(sum(r["n_leak"] for r in rs), sum(r["n_gt_shadowed"] for r in rs))
             if split else math.nan,
             "error_pooled": _pooled(sum(r["n_acne"] + r["n_peterpan"] for r in rs),
                                     sum(r["n_receivers"] for r in rs)),
             "build_ms": float(np.mean([r["build_ms"] for r in rs])),
             "lookup_ms": float(np.mean([r["lookup_ms"] for r in rs])),
             "best_in": best.get(key, 0)}
        for rate, tag in (("acne_rate", "acne"), ("peterpan_rate", "peterpan"), ("error_rate", "error")):
            for k, v in _stats([r[rate] for r in rs]).items():
                s[f"{tag}_{k}"] = v
        out.append(s)
    out.sort(key=lambda s: (not defined(s["error_pooled"]), s["error_pooled"] if defined(s["error_pooled"]) else 0,
                            instance_label(s["key"])))
    return out


def best_per_group(rows) -> list:
    """Per (scene, light, resolution): the best instance by pooled error rate; dicts with scene,
    light, resolution, label (the first by label of those at the lowest rate), error (that rate),
    tied (how many others are at it) and labels (every one at it, by label)."""
    multi = _multi(rows)
    groups = {}
    for r in rows:
        groups.setdefault((r["scene"], r["light"], r["resolution"]), {}).setdefault(
            instance_key(r, multi), []).append(r)
    out = []
    for (scene, light, res), inst in groups.items():
        scored = []
        for key, rs in inst.items():
            e = _pooled(sum(r["n_acne"] + r["n_peterpan"] for r in rs), sum(r["n_receivers"] for r in rs))
            if defined(e):
                scored.append((e, instance_label(key)))
        if not scored:
            out.append({"scene": scene, "light": light, "resolution": res, "label": "-", "error": math.nan, "tied": 0,
                        "labels": []})
            continue
        e = min(t[0] for t in scored)
        labels = sorted(label for x, label in scored if x == e)
        out.append({"scene": scene, "light": light, "resolution": res, "label": labels[0], "error": e,
                    "tied": len(labels) - 1, "labels": labels})
    return out


def rate(x) -> str:
    """A rate for a table: '-' when undefined, 3 significant digits."""
    if not defined(x):
        return "-"
    return "0" if x == 0 else f"{x:.3g}"


def _ms(x) -> str:
    return f"{x:.2f}" if x < 10 else f"{x:.1f}"


def summary_columns(rows) -> list:
    """The summary's identifying columns: scheme, params and whichever of filter, format, layout vary."""
    return ["scheme", "params", *_multi(rows)]


def summary_md(rows) -> list:
    """Markdown lines: the per-instance table with its definitions, then the best per scene,
    light and resolution (a row per scene and light, a column per resolution)."""
    if not rows:
        return []
    multi = _multi(rows)
    extra = ", with " + " and ".join(multi) if multi else ""
    head = summary_columns(rows)
    split = has_leak_split(rows)          # the leak column only where the run has it: others unchanged
    shown = lambda text: labels.params_label(text, exact=True)     # as the console and report name a bias
    out = ["## Summary", "", f"**{shown(answer(rows))}**", "",
           DEFINITIONS.format(extra=extra) + (LEAK_COLUMN_DEFINITION if split else ""), "",
           "| " + " | ".join(head) + " | cases | acne pooled | acne mean / median / max | peter-pan pooled | "
           "peter-pan mean / median / max | " + ("leak pooled | " if split else "") + "error pooled | "
           "error mean / median / max | undefined acne / peter-pan / error | build ms | lookup ms | best in |",
           "|---" * (len(head) + 11 + split) + "|"]
    for s in per_instance(rows):
        trio = lambda t: f"{rate(s[t + '_mean'])} / {rate(s[t + '_median'])} / {rate(s[t + '_max'])}"
        leak = f"{rate(s['leak_pooled'])} | " if split else ""
        out.append("| " + " | ".join(shown(str(s[h])) for h in head) + f" | {s['cases']} | {rate(s['acne_pooled'])} | "
                   f"{trio('acne')} | {rate(s['peterpan_pooled'])} | {trio('peterpan')} | {leak}"
                   f"{rate(s['error_pooled'])} | {trio('error')} | {s['acne_undefined']} / "
                   f"{s['peterpan_undefined']} / {s['error_undefined']} | {_ms(s['build_ms'])} | "
                   f"{_ms(s['lookup_ms'])} | {s['best_in']} |")
    out += leak_md(rows)
    out += ["", "## Best per scene, light and resolution", "", BEST_DEFINITION, ""] + best_md(rows)
    return out


LEAK_DEFINITION = ("A run that gives [map] kind splits each case's peter-panning by where it is in the exact "
                   "shadow: *edge* within leak_texels texels of an exactly lit point of the receiver's own surface "
                   "(the shadow's outline, which resolution and bias decide), *leak* deeper inside (light leaking: "
                   "false light the filtered statistics let through; exact shadow rays around the receiver tell "
                   "the two). Per "
                   "scheme instance (a pre-filtered kind's filter is its blur box:W): pooled over its cases, each "
                   "over sum n_gt_shadowed; mean abs error: the mean of the cases' mean |V - V*|; moments ms: the "
                   "mean build of a pre-filtered map's moments and blur. Sorted by pooled leak rate.")


def leak_md(rows) -> list:
    """Markdown lines of the light-leaking table, for a run whose rows carry the leak split (else none)."""
    if not has_leak_split(rows):
        return []
    multi = _multi(rows)
    head = summary_columns(rows)
    groups = {}
    for r in rows:
        groups.setdefault(instance_key(r, multi), []).append(r)
    table = []
    for key, rs in groups.items():
        shadowed = sum(r["n_gt_shadowed"] for r in rs)
        s = {"scheme": key[0], "params": key[1], **dict(zip(multi, key[2:]))}
        table.append(([str(s[h]) for h in head], rs[0]["map_kind"], len(rs),
                      _pooled(sum(r["n_peterpan"] for r in rs), shadowed),
                      _pooled(sum(r["n_peterpan_edge"] for r in rs), shadowed),
                      _pooled(sum(r["n_leak"] for r in rs), shadowed),
                      _stats([r["mean_abs_error"] for r in rs])["mean"],
                      _stats([r["moments_ms"] for r in rs])["mean"]))
    table.sort(key=lambda t: (not defined(t[5]), t[5] if defined(t[5]) else 0))
    out = ["", "## Light leaking", "", LEAK_DEFINITION, "",
           "| " + " | ".join(head) + " | map kind | cases | peter-pan pooled | edge pooled | leak pooled | "
           "mean abs error | moments ms |", "|---" * (len(head) + 7) + "|"]
    for cells, kind, n, pp, contact, leak, mae, mom in table:
        out.append("| " + " | ".join(cells) + f" | {kind} | {n} | {rate(pp)} | {rate(contact)} | {rate(leak)} | "
                   f"{rate(mae)} | {_ms(mom) if defined(mom) else '-'} |")
    return out


def best_pivot(rows):
    """(resolutions, [(scene, light, {resolution: best dict})]) in the order the run met them."""
    best = best_per_group(rows)
    resolutions = sorted({b["resolution"] for b in best})
    pivot = {}
    for b in best:
        pivot.setdefault((b["scene"], b["light"]), {})[b["resolution"]] = b
    return resolutions, [(s, l, cells) for (s, l), cells in pivot.items()]


def best_cell(b) -> str:
    """A best-per-group cell: the instance and its pooled error rate, or a tie said as one; '' for none."""
    if b is None:
        return ""
    if not b["tied"]:
        return f"{b['label']} ({rate(b['error'])})"
    return f"{b['tied'] + 1} tied ({rate(b['error'])}): {tie_words(b['labels'])}"


def tie_words(labels: list) -> str:
    """A tie's instances: every label up to TIE_NAMES + 1, else their families (each label's first word)
    and how many of each, most first (the full list is the table's and the page's)."""
    if len(labels) <= TIE_NAMES + 1:
        return names(labels)
    return ", ".join(f"{f} {n}" if n > 1 else f for f, n in frontier.family_counts(x.split()[0] for x in labels))


def names(labels: list) -> str:
    """Labels as words: all of them up to TIE_NAMES + 1, else the first TIE_NAMES and how many more."""
    if len(labels) <= TIE_NAMES + 1:
        return ", ".join(labels[:-1]) + " and " + labels[-1] if len(labels) > 1 else labels[0]
    return ", ".join(labels[:TIE_NAMES]) + f" and {len(labels) - TIE_NAMES} more"


def answer(rows) -> str:
    """Two sentences: the lowest pooled error rate over the run (a tie said as one), and the
    instances alone the best in the most situations (outright wins only)."""
    insts = [s for s in per_instance(rows) if defined(s["error_pooled"])]
    if not insts:
        return "No case of this run has a defined error rate."
    low = [instance_label(s["key"]) for s in insts if s["error_pooled"] == insts[0]["error_pooled"]]
    first = (f"Lowest pooled error rate over all {len(rows)} cases: {low[0]} ({rate(insts[0]['error_pooled'])})."
             if len(low) == 1 else f"Lowest pooled error rate over all {len(rows)} cases "
             f"({rate(insts[0]['error_pooled'])}): a tie of {len(low)}, {names(sorted(low))}.")
    n = len({tuple(r[k] for k in SITUATION) for r in rows})
    most = max(s["best_in"] for s in insts)
    if most == 0:
        return first + f" No instance is alone the best in any of the {n} situations (each best is a tie)."
    top = sorted(instance_label(s["key"]) for s in insts if s["best_in"] == most)
    return first + (f" Most often alone the best: {names(top)} (in {most} of {n} situations"
                    + (" each)." if len(top) > 1 else ")."))


def best_md(rows) -> list:
    """Markdown lines of the best instance per scene and light (rows) and resolution (columns)."""
    resolutions, pivot = best_pivot(rows)
    out = ["| scene | light | " + " | ".join(f"R = {r}" for r in resolutions) + " |",
           "|---" * (2 + len(resolutions)) + "|"]
    for scene, light, cells in pivot:
        out.append(f"| {scene} | {light} | " + " | ".join(labels.params_label(best_cell(cells.get(r)), exact=True)
                                                            for r in resolutions) + " |")
    return out


def best_per_light(rows) -> list:
    """Per (light, resolution), pooled over the scenes: dicts as best_per_group's (label, error, tied,
    labels), a tie said as one; the terminal's first answer."""
    return best_per_group([{**r, "scene": "every scene"} for r in rows])


def terminal_answer(rows, most: int = 12) -> list:
    """The lines ``dsm run`` ends with: what accuracy costs (dsm.report.frontier), the headline (answer)
    and the best instance per light and resolution over every scene (at most ``most`` lines; the rest named by count)."""
    if not rows:
        return []
    best = best_per_light(rows)
    found = frontier.answers(frontier.points_from_rows(rows))
    lines = frontier.answer_lines(found) + frontier.time_lines(found) + [answer(rows)] + [
        f"best for light {b['light']} {pooled_scenes(rows, b['light'])} at R = {b['resolution']}: {best_cell(b)}"
        for b in best[:most]]
    if len(best) > most:
        lines.append(f"... and {len(best) - most} more lights and resolutions (table.md)")
    # the report's labels (2^-24 range), each other number as the run wrote it: the console has no hover
    return [labels.params_label(line, exact=True) for line in lines]


def pooled_scenes(rows, light) -> str:
    """What a per-light best pools: ``over 5 scenes``, or ``in plane_box`` where the light lights one."""
    scenes = sorted({r["scene"] for r in rows if r["light"] == light})
    return f"in {scenes[0]}" if len(scenes) == 1 else f"over {len(scenes)} scenes"
