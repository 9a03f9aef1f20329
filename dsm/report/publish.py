"""The report of a run, written after its measurements; ``dsm report``: rebuilt from a run's files,
or two runs compared.

A run writes its data files (:func:`write_data`: oracle.csv, cascades.csv, cascade_curves.csv,
frames.csv beside the metrics.csv and run.json it writes as it goes, and images/), then calls
:func:`write_report` once its timed work is done: this module is the only composer of the
report, and it reads nothing but those files, so :func:`rebuild` (``dsm report DIR``) writes the
same report from the same folder: table.md, cascades.md, the figures (the oracles' trade-off
plots, the cascades' distance plots, the flicker plots, the soft-shadow plots) and report.html.
The figures are drawn after the timed work (in worker processes when there are enough, see
``jobs.run_jobs``), so no drawing overlaps a timed build or lookup.
"""
from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path

from . import derivation, figures, frontier, html as htmlpage, jobs as draw_jobs, tables as report, io as report_io, summary
from ..truth import metrics
from .sections import cascades, motion
from .sections import soft as soft_report
from .sections import hybrid as hybrid_report
from .sections import virtual as virtual_report
from .sections import cache as cache_report

PLOT_PREFIXES = ("vs_bias_", "vs_resolution_", "vs_texels_", "pareto_", "tradeoff_", "soft_", "cascades_", "flicker_",
                 "hybrid_", cache_report.PLOT_PREFIX)
IMAGES_PER_JOB = 150


class NotARun(ValueError):
    """A folder that holds no dsm run (no metrics.csv or run.json)."""


def image_item(row: dict, classes, shade, mode: str = "all"):
    """What write_report writes for one case under ``[report] images = mode``: its error image
    (classes, (H, W) uint8), and with "all" its shadow-mapped render (shade, (H, W) in [0, 1]);
    None for "none"."""
    if mode == "none":
        return None
    err, shadow = figures.image_paths(row)
    return err, classes, shadow, figures.shade_image(shade) if mode == "all" else None


def _read_rows(path: Path, notes: list, needs: str | None = None) -> list:
    """A run's CSV as typed rows; a row cut short (a run killed while writing it) is left out and
    noted; a file that is not the kit's is NotARun."""
    try:
        raw = report_io.read_csv(path)
        with open(path, newline="") as fh:
            header = next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise NotARun(f"{path}: cannot be read ({e})") from None
    if needs and needs not in header:
        raise NotARun(f"{path}: not a dsm {path.name} (no {needs!r} column)")
    whole = report_io.whole_rows(raw)
    if len(whole) < len(raw):
        notes.append(f"{path}: {len(raw) - len(whole)} row(s) cut short (a run killed while writing them) left out")
    try:
        return report_io.typed_rows(whole)
    except (TypeError, ValueError) as e:
        raise NotARun(f"{path}: a cell that is not a number where one belongs ({e})") from None


def _load(out: Path, notes: list | None = None):
    out = Path(out)
    notes = [] if notes is None else notes
    if (out / "tune.json").is_file() and not (out / "run.json").is_file():
        raise NotARun(f"{out}: a dsm tune folder, not a run's: its table.md and tuned.toml are its report")
    if not (out / "metrics.csv").is_file() or not (out / "run.json").is_file():
        raise NotARun(f"{out}: not a dsm results folder (it needs metrics.csv and run.json)")
    try:
        run = json.loads((out / "run.json").read_text())
    except (OSError, ValueError) as e:
        raise NotARun(f"{out}/run.json: not a dsm run.json ({e})") from None
    if not isinstance(run, dict):
        raise NotARun(f"{out}/run.json: not a dsm run.json (not a JSON object)")
    rows = _read_rows(out / "metrics.csv", notes, "case")
    _check_metrics(out / "metrics.csv", rows)
    _check_costs(out / "metrics.csv", rows)
    _note_missing(out, run, rows, notes)
    oracle_rows = _read_rows(out / "oracle.csv", notes) if (out / "oracle.csv").is_file() else []
    return run, rows, oracle_rows


def _note_missing(out: Path, run: dict, rows: list, notes: list):
    """Notes for what the report lacks against run.json: finished cases without a row, oracle.csv."""
    finished = {s["what"].split()[1] for s in run.get("status", []) if isinstance(s, dict)
                and str(s.get("what", "")).startswith("case ") and s.get("status") in ("ok", "empty")}
    lost = finished - {r["case"] for r in rows}
    if lost:
        notes.append(f"{out / 'metrics.csv'}: {len(lost)} case(s) run.json lists as finished have no row "
                     f"({', '.join(sorted(lost)[:3])}{', ...' if len(lost) > 3 else ''}): left out of the report")
    if rows and not (out / "oracle.csv").is_file() and any(r["filter"] == "nearest" for r in rows):
        notes.append(f"{out / 'oracle.csv'} is absent: table.md has no \"How far from the best\" section")


def write_data(out: Path, rec):
    """The run's data files beside metrics.csv and run.json, from its record (dsm.core.record): what
    the report is composed from."""
    out = Path(out)
    report.write_oracle_csv(out / "oracle.csv", rec.oracle_rows)
    if rec.cascade_rows:
        cascades.write_csv(out / "cascades.csv", rec.cascade_rows)
        cascades.write_curves_csv(out / "cascade_curves.csv", rec.cascade_curves)
    if rec.motion_frames:
        motion.write_frames_csv(out / "frames.csv", rec.motion_frames)


def _sections(out: Path, notes: list, plots: bool):
    """The sections of runs with cascades (cascades.md, plots/cascades_*.png) and motion
    (plots/flicker_*.png), from cascades.csv, cascade_curves.csv and frames.csv."""
    if (out / "cascades.csv").is_file():
        cascades.write_table(out / "cascades.md", _read_rows(out / "cascades.csv", notes, "case"))
        if plots and (out / "cascade_curves.csv").is_file():
            cascades.write_plots(out / "plots", cascades.read_curves_csv(out / "cascade_curves.csv"))
    if plots and (out / "frames.csv").is_file():
        motion.write_plots(out / "plots", report_io.read_csv(out / "frames.csv"))


RATES = (("acne_rate", "n_acne", "n_gt_lit"), ("peterpan_rate", "n_peterpan", "n_gt_shadowed"))


def _check_metrics(path: Path, rows: list):
    """NotARun unless every row has the core columns and rates that are their counts' (within
    the 6 significant digits metrics.csv keeps): an edited or foreign file is not reported on."""
    from ..core.record import GROUPS
    missing = sorted(GROUPS["core"] - set(rows[0])) if rows else []
    if missing:
        raise NotARun(f"{path}: not a dsm metrics.csv (no {', '.join(missing)} column)")
    seen = set()
    for r in rows:
        if r["case"] in seen:
            raise NotARun(f"{path}: case {r['case']} appears twice: an edited file")
        seen.add(r["case"])
        if r.get("motion"):           # a motion case's rates are means over its frames, its counts sums
            continue
        for rate, num, den in RATES + (("error_rate", None, "n_receivers"),):
            n = r["n_acne"] + r["n_peterpan"] if num is None else r[num]
            want = n / r[den] if r[den] else metrics.UNDEFINED
            got = r[rate]
            if metrics.defined(want) != metrics.defined(got) or (metrics.defined(want) and
                                                                  abs(got - want) > 1e-5 * max(abs(want), 1e-300)):
                raise NotARun(f"{path}: case {r['case']}: {rate} {got} is not {'n_acne + n_peterpan' if num is None else num}"
                              f" / {den} ({want:.6g}): an edited file")


HYBRID_COUNTS = ("hybrid_rays", "hybrid_n_acne", "hybrid_n_peterpan")


def _check_costs(path: Path, rows: list):
    """NotARun unless the cost columns (the frontier's) are all absent (a run from before them) or all
    there, each row's a count >= 0 (taps a number >= 0, NaN without receivers), and a hybrid row's rays
    and error left counts too: an edited file is not put on a frontier."""
    from ..core.record import GROUPS
    cost = sorted(GROUPS["cost"])
    held = [c for c in cost if rows and c in rows[0]]
    if held and len(held) < len(cost):
        raise NotARun(f"{path}: has {held[0]} but no {sorted(set(cost) - set(held))[0]} column: an edited file "
                      f"(a run writes all of {', '.join(cost)} or, before them, none)")
    for r in rows if held else ():
        whole = [c for c in cost if c != "taps"] + [c for c in HYBRID_COUNTS if r.get("hybrid_rule")]
        for c in whole:
            v = r.get(c)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
                    and float(v).is_integer()):
                raise NotARun(f"{path}: case {r['case']}: {c} {v!r} is not a count (a whole number >= 0): "
                              "an edited file")
        if not (r["taps"] != r["taps"] or 0 <= r["taps"] < math.inf):
            raise NotARun(f"{path}: case {r['case']}: taps {r['taps']!r} is not texels read per lookup "
                          "(a number >= 0): an edited file")


def _texels(run) -> tuple:
    """The config's ``[map] texels`` as run.json recorded it (none where the record is damaged)."""
    cfg = run.get("config")
    mp = cfg.get("map") if isinstance(cfg, dict) else None
    raw = mp.get("texels", []) if isinstance(mp, dict) else []
    return tuple(raw if isinstance(raw, list) else [raw])


def write_report(out: Path, images=(), curves=None, plots: bool = True) -> dict:
    """Write the report of the run in ``out``: case images (``images``: image_item()s), figures
    (``plots``), table.md and report.html. ``curves``: the oracles' exact curves of the run
    (saved as oracle_curves.npz); None reads that file. Returns seconds spent per part."""
    out = Path(out)
    t0 = time.perf_counter()
    notes = []
    run, rows, oracle_rows = _load(out, notes)
    derived = derivation.read(out, notes)
    if curves is not None:
        rates = [figures.curve_rates(*c) for c in curves]
        figures.save_curves(out / "oracle_curves.npz", rates)
    else:
        try:
            rates = figures.load_curves(out / "oracle_curves.npz")
        except Exception as e:          # numpy raises ValueError, OSError, zipfile's BadZipFile, KeyError...
            notes.append(f"{out / 'oracle_curves.npz'}: unreadable ({type(e).__name__}), so the trade-off plots "
                         "have no oracle curves")
            rates = []
    jobs = []
    if plots and rows:
        folder = out / "plots"
        folder.mkdir(exist_ok=True)
        for p in folder.glob("*.png"):           # a rebuild replaces every figure a run draws
            if p.name.startswith(PLOT_PREFIXES):
                p.unlink()
        jobs += figures.plot_jobs(folder, rows, rates)
        jobs += soft_report.plot_jobs(folder, rows)          # area lights: MAE of V against V* by region
        jobs += hybrid_report.plot_jobs(folder, rows)        # [hybrid]: error against rays per receiver
    n_figures = len(jobs)
    items = [i for i in images if i is not None]
    by_folder = {}
    for it in items:
        by_folder.setdefault(Path(it[0]).parent, []).append(it)
    for its in by_folder.values():
        jobs += [(figures.write_images, (out, its[i:i + IMAGES_PER_JOB])) for i in range(0, len(its), IMAGES_PER_JOB)]
    t1 = time.perf_counter()
    pool = draw_jobs.run_jobs(jobs)
    t2 = time.perf_counter()
    report.write_table(out / "table.md", rows, run.get("experiment", out.name), run.get("config_file", ""),
                       run.get("status", []), oracle_rows, _texels(run), state=run.get("state"),
                       planned=run.get("plan", {}).get("cases"), derived=derivation.md_lines(derived))
    _sections(out, notes, plots and bool(rows))
    points = frontier.points_from_rows(rows)
    if points:                          # a run from before the cost columns has no frontier (table.md says so)
        frontier.write_csv(out / "frontier.csv", points)
    elif (out / "frontier.csv").is_file():      # one of rows no longer there: not this report's
        (out / "frontier.csv").unlink()
    virtual_report.write_table(out / "virtual.md", rows)
    cache_report.write_table(out / "cache.md", rows)
    if plots and rows:
        cache_report.write_plots(out / "plots", rows)
    hybrid_report.write_table(out / "hybrid.md", rows)
    htmlpage.write_html(out / "report.html", rows, run, derived)
    t3 = time.perf_counter()
    return {"figures": n_figures, "images": len(items), "workers": pool, "read_s": t1 - t0, "draw_s": t2 - t1,
            "pages_s": t3 - t2, "notes": notes}


def rebuild(out: Path, plots: bool = True) -> dict:
    """``dsm report DIR``: table.md, the plots and report.html again from the folder's files,
    without measuring (the case images are kept as they are)."""
    return write_report(out, (), None, plots)


# ------------------------------------------------------------------ comparing two runs

KEY = ("scene", "light", "view", "scheme", "params", "resolution", "filter", "format", "culling", "cascade_layout")
COMPARED = ("acne_rate", "peterpan_rate", "error_rate", "n_acne", "n_peterpan", "n_receivers", "build_ms",
            "lookup_ms")


def _key(r):
    return tuple(r["preset"] or r["params"] if k == "params" else r.get(k, "") for k in KEY)


def _diff(a, b):
    return b - a if metrics.defined(a) and metrics.defined(b) else math.nan


def _signed(x) -> str:
    if not metrics.defined(x):
        return "-"
    return "0" if x == 0 else f"{x:+.3g}"


COUNTS = ("n_receivers", "n_acne", "n_peterpan")


def count_share(a, b) -> float:
    """The largest difference of the two cases' receiver, acne and peter-panning counts, as a
    share of A's receivers (0 when the counts are identical; the counts themselves over an empty
    case)."""
    return max(abs(int(b[k]) - int(a[k])) for k in COUNTS) / max(int(a["n_receivers"]), 1)


def _count_lines(pairs) -> list:
    """compare.md's counts section: how many matched cases have identical counts, and the largest
    count difference as a share of receivers, overall and per scheme (two variants, machines or
    commits on one config)."""
    shares = [(count_share(a, b), a) for a, b in pairs]
    lines = ["## Counts (receivers, acne, peter-panning)", "",
             f"{sum(1 for s, _ in shares if s == 0)} of {len(pairs)} matched cases have identical counts; the largest "
             f"difference is {100 * max((s for s, _ in shares), default=0.0):.3f} % of a case's receivers.", "",
             "| scheme | cases | identical | largest difference (% of receivers) |", "|---|---|---|---|"]
    per = {}
    for s, a in shares:
        per.setdefault(a["scheme"], []).append(s)
    for name, v in per.items():
        lines.append(f"| {name} | {len(v)} | {sum(1 for s in v if s == 0)} | {100 * max(v):.3f} |")
    return lines + [""]


def compare(dir_a: Path, dir_b: Path, out: Path) -> dict:
    """``dsm report A B``: the cases both runs hold (same scene, light, view, scheme instance,
    resolution, filter, format and culling), side by side with B - A, into ``out``: compare.md
    (how many matched cases have identical counts and the largest count difference, the
    per-instance summaries of the matched cases of each run, then every matched case, the
    largest change in error rate first) and compare.csv (every matched case, a_, b_ and diff_
    columns). Returns the counts."""
    run_a, rows_a, _ = _load(dir_a)
    run_b, rows_b, _ = _load(dir_b)
    index_b = {}
    for r in rows_b:
        index_b.setdefault(_key(r), r)
    pairs, seen = [], set()
    for r in rows_a:
        k = _key(r)
        if k in index_b and k not in seen:
            pairs.append((r, index_b[k]))
            seen.add(k)
    only_a = sum(1 for r in rows_a if _key(r) not in index_b)
    only_b = sum(1 for r in rows_b if _key(r) not in seen)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _write_compare_csv(out / "compare.csv", pairs)
    desc = lambda run, d: (f"`{d}` ({run.get('experiment', '?')}, {run.get('state', '?')}, commit "
                           f"{str(run.get('versions', {}).get('dsm_git_commit', '?'))[:10]}, "
                           f"{run.get('variant', '?')}, {run.get('threads', '?')} threads)")
    lines = ["# Comparison: B - A", "", f"A: {desc(run_a, dir_a)}", "", f"B: {desc(run_b, dir_b)}", "",
             f"{len(pairs)} cases in both (matched on {', '.join(KEY)}); {only_a} only in A, {only_b} only in B. "
             "Differences are B - A; a dash: undefined in either run.", ""]
    lines += _count_lines(pairs) + _instance_lines(pairs) + _case_lines(pairs)
    with report_io.atomic(out / "compare.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return {"matched": len(pairs), "only_a": only_a, "only_b": only_b,
            "identical_counts": sum(1 for a, b in pairs if count_share(a, b) == 0)}


def _write_compare_csv(path: Path, pairs: list):
    """compare.csv: every matched case, its key, both case ids, and a_, b_ and diff_ per compared column."""
    with report_io.atomic(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(KEY) + ["case_a", "case_b"] + [f"{p}_{c}" for c in COMPARED for p in ("a", "b", "diff")])
        for a, b in pairs:
            w.writerow(list(_key(a)) + [a["case"], b["case"]] + [
                f"{x:.6g}" if metrics.defined(x) else ""
                for c in COMPARED for x in (float(a[c]), float(b[c]), _diff(a[c], b[c]))])


def _instance_lines(pairs: list) -> list:
    """compare.md's per-instance section: each run's pooled rates and times over the matched cases."""
    lines = ["## Per scheme instance, over the matched cases", "",
             "| scheme | params | cases | acne pooled A | B | B - A | peter-pan pooled A | B | B - A | "
             "error pooled A | B | B - A | build ms A | B | lookup ms A | B |", "|---" * 16 + "|"]
    sa = {s["key"][:2]: s for s in summary.per_instance([a for a, _ in pairs])} if pairs else {}
    sb = {s["key"][:2]: s for s in summary.per_instance([b for _, b in pairs])} if pairs else {}
    for k, a in sa.items():
        b = sb.get(k)
        if b is None:
            continue
        cells = [k[0], k[1], a["cases"]]
        for t in ("acne_pooled", "peterpan_pooled", "error_pooled"):
            cells += [summary.rate(a[t]), summary.rate(b[t]), _signed(_diff(a[t], b[t]))]
        cells += [f"{a['build_ms']:.2f}", f"{b['build_ms']:.2f}", f"{a['lookup_ms']:.2f}", f"{b['lookup_ms']:.2f}"]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    return lines


def _case_lines(pairs: list) -> list:
    """compare.md's matched cases, the largest change in error rate first (undefined changes last)."""
    lines = ["", "## Matched cases (largest change in error rate first)", "",
             "| case A | case B | scene | light | view | scheme | params | R | filter | format | acne A | B | B - A | "
             "peter-pan A | B | B - A | error A | B | B - A | time ms A | B |", "|---" * 21 + "|"]
    change = lambda p: _diff(p[0]["error_rate"], p[1]["error_rate"])
    order = sorted(pairs, key=lambda p: (not metrics.defined(change(p)),
                                         -abs(change(p)) if metrics.defined(change(p)) else 0))
    for a, b in order:
        cells = [a["case"], b["case"], a["scene"], a["light"], a["view"], a["scheme"], a["preset"] or a["params"],
                 a["resolution"], a["filter"], a["format"]]
        for c in ("acne_rate", "peterpan_rate", "error_rate"):
            cells += [summary.rate(a[c]), summary.rate(b[c]), _signed(_diff(a[c], b[c]))]
        cells += [f"{report.case_time(a):.2f}", f"{report.case_time(b):.2f}"]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    return lines
