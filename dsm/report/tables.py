"""Report: metrics.csv (written row by row), table.md, run.json, oracle.csv. The figures are
dsm.report.figures', report.html dsm.report.html's, and dsm.report.publish writes them all after a run."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .sections import contact as contact_report
from ..maps import headroom
from ..truth import metrics
from ..core import record
from . import frontier, io as report_io, summary

COLUMNS = record.NAMES          # metrics.csv's columns: the run record's schema (dsm.core.record)


def progress(total: int, enabled: bool):
    """A tqdm bar over ``total`` cases, shown only when ``enabled`` and stderr is a terminal."""
    from tqdm import tqdm
    return tqdm(total=total, unit="case", disable=not enabled or not sys.stderr.isatty(), dynamic_ncols=True)


# ------------------------------------------------------------------ images

def shade(classes_shape, gb, setup, v: np.ndarray, positional: bool, cosines=None) -> np.ndarray:
    """The shadow-mapped render of one case (H, W) in [0, 1]: Lambert under the light with the
    map's visibility, ambient elsewhere. ``positional``: the light sits at its position (else it
    shines along its direction; dsm.lights). ``cosines``: receiver_cosines(setup, positional),
    given when the caller keeps it for the many cases of one set of receivers."""
    out = np.zeros(gb.width * gb.height)
    out[gb.hit] = 0.12
    if setup.n is not None:
        cos = receiver_cosines(setup, positional) if cosines is None else cosines
        out[setup.pixels] = 0.12 + 0.88 * cos * v
    return out.reshape(classes_shape)


def receiver_cosines(setup, positional: bool) -> np.ndarray:
    """Each receiver's cosine to the light, clipped at 0 (float64, per receiver)."""
    n = np.stack([c.numpy() for c in (setup.n.x, setup.n.y, setup.n.z)], 1)
    to_light = _to_light_np(setup, n.shape[0], positional)
    return np.clip((n * to_light).sum(1), 0, 1)


def _to_light_np(setup, count, positional):
    light = setup.light
    if not positional:
        d = -np.asarray(light.direction, float)
        return np.broadcast_to(d / np.linalg.norm(d), (count, 3))
    p = np.stack([c.numpy() for c in (setup.p.x, setup.p.y, setup.p.z)], 1)
    d = np.asarray(light.position, float) - p
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)


# ------------------------------------------------------------------ table

TABLE_COLUMNS = [("scene", "scene"), ("light", "light"), ("resolution", "R"), ("scheme", "scheme"),
                 ("params", "params"), ("acne_rate", "acne"), ("n_acne_self", "self"), ("n_acne_edge", "edge"),
                 ("peterpan_rate", "peter-pan"), ("peterpan_dist_median", "pp dist"), ("error_rate", "error"),
                 ("build_ms", "build ms"), ("lookup_ms", "lookup ms"), ("reference_ms", "ref ms")]


def legend_md() -> str:
    """The Markdown line naming the error images' class colours (``rgb(r, g, b)`` each)."""
    items = [f"{name}: rgb{tuple(int(c) for c in col)}" for name, col in zip(metrics.CLASS_NAMES, metrics.CLASS_COLORS)]
    return "Error images (`images/<scene>_<light>/<case>_error.png`): " + "; ".join(items) + "."


def status_md(status) -> list:
    """Markdown lines listing what failed (with its reason), what was skipped and the empty cases."""
    status = status or []
    out = []
    failed = [x for x in status if x["status"] == "failed"]
    if failed:
        out += ["", f"## Failed ({len(failed)})", "", "| what | error |", "|---|---|"]
        out += [f"| {x['what']} | {str(x.get('error', '')).replace('|', '/')} |" for x in failed]
    skipped = [x for x in status if x["status"] == "skipped"]
    if skipped:
        out += ["", f"## Skipped ({len(skipped)})", ""] + [f"- {x['what']}: {x.get('error', '')}" for x in skipped]
    empty = [x for x in status if x["status"] == "empty"]
    if empty:
        groups = {}
        for x in empty:
            groups.setdefault((x.get("scene"), x.get("light"), x.get("view")), []).append(x["what"].split()[-1])
        out += ["", f"## Empty cases ({len(empty)})", "",
                "No camera pixel is a receiver of this light and view (nothing faces the light inside its "
                "domain), so these cases say nothing about a scheme; their rates are undefined (-)."]
        out += [f"- {sc}, light {li}, {vi}: {len(c)} cases ({c[0]} to {c[-1]})" for (sc, li, vi), c in groups.items()]
    return out


# ------------------------------------------------------------------ oracles

ORACLE_COLUMNS = ["scene", "light", "view", "resolution", "culling", "format", "lambda", "n_receivers", "n_gt_lit",
                  "n_gt_shadowed", "best_b", "best_k"] + [
    f"{o}_{q}" for o in ("world", "texel", "per_texel")
    for q in ("objective", "acne_rate", "peterpan_rate", "n_acne", "n_peterpan")]


def write_oracle_csv(path: Path, rows: list):
    """oracle.csv: one row per map, stored format and lambda (written atomically); the best
    biases exactly, so pasted into a config they give the oracle's counts."""
    report_io.write_csv(path, ORACLE_COLUMNS, rows, exact=("best_b", "best_k"))


def objective(r, lam: float = 1.0) -> float:
    """E(lambda) = (n_acne + lambda n_peterpan) / n_receivers of a case row (undefined without receivers)."""
    return (r["n_acne"] + lam * r["n_peterpan"]) / r["n_receivers"] if r["n_receivers"] else metrics.UNDEFINED


def _map_key(r):
    return (r["scene"], r["light"], r["view"], r["resolution"], r["culling"], r["format"])


def oracle_md(rows: list, oracle_rows: list) -> list:
    """table.md's "How far from the best": per scheme instance (nearest cases), its mean objective
    beside the mean of the oracles of the same maps; then each map's oracles and its best case."""
    if not oracle_rows:
        return []
    lam = oracle_rows[0]["lambda"]
    orc = {_map_key(o): o for o in oracle_rows if o["lambda"] == lam}
    near = [r for r in rows if r["filter"] == "nearest" and _map_key(r) in orc and r["n_receivers"]]
    out = ["", "## How far from the best", "",
           f"Objective E = (n_acne + lambda n_peterpan) / receivers, lambda = {lam:g} (nearest lookup). Oracles, "
           "exact over each map's receivers: *world*, the best single depth bias b for the map; *texel*, the best "
           "single k with b = k texel; *per texel*, the best b chosen in each texel separately (no bias scheme "
           "that reads only the texel can do better: the rest is the resolution's). Means over the scheme's "
           "nearest cases and the oracles of the same maps (oracle.csv has every map, format and lambda).", "",
           "| scheme | params | cases | E | world oracle | texel oracle | per-texel oracle | E - world |",
           "|---|---|---|---|---|---|---|---|"]
    groups = {}
    for r in near:
        groups.setdefault((r["scheme"], r["preset"] or r["params"]), []).append(r)
    for (scheme, params), rs in groups.items():
        e = np.mean([objective(r, lam) for r in rs])
        ow = np.mean([orc[_map_key(r)]["world_objective"] for r in rs])
        ok = np.mean([orc[_map_key(r)]["texel_objective"] for r in rs])
        op = np.mean([orc[_map_key(r)]["per_texel_objective"] for r in rs])
        out.append(f"| {scheme} | {params} | {len(rs)} | {e:.4f} | {ow:.4f} | {ok:.4f} | {op:.4f} | {e - ow:+.4f} |")
    out += ["", "| scene | light | view | R | culling | format | best b | E world | best k | E texel | "
                "E per texel | best case | its E |", "|---" * 13 + "|"]
    by_map = {}
    for r in near:
        by_map.setdefault(_map_key(r), []).append(r)
    for key, o in orc.items():
        rs = by_map.get(key, [])
        bc = min(rs, key=lambda r: objective(r, lam)) if rs else None
        out.append(f"| {' | '.join(map(str, key))} | {o['best_b']:.4g} | {_cell(o['world_objective'])} | "
                   f"{o['best_k']:.4g} | {_cell(o['texel_objective'])} | {_cell(o['per_texel_objective'])} | "
                   + (f"{bc['scheme']} {bc['preset'] or bc['params']} | {objective(bc, lam):.4f} |" if bc else "- | - |"))
    return out


def unfinished_md(state, planned, n_rows: int) -> list:
    """A line saying that the run stopped before its plan was done (its summary covers only the
    cases that ran), or nothing for a complete run."""
    if state not in ("interrupted", "running"):
        return []
    of = f" of the {planned} planned" if planned else ""
    how = "was interrupted" if state == "interrupted" else "did not finish (state: running)"
    return [f"**This run {how}: {n_rows}{of} cases ran, and everything below covers those only. "
            "`dsm run CONFIG --out DIR --resume` runs the rest.**", ""]


def precision_md(rows: list) -> list:
    """A section naming the cases whose map is limited by float32 (dsm.maps.headroom), or nothing."""
    line = headroom.summary(rows)
    if not line:
        return []
    few = headroom.limited(rows)
    return ["", f"## Float32 precision ({len(few)} cases)", "", line[0].upper() + line[1:] + ".",
            "Cases: " + ", ".join(r["case"] for r in few[:40]) + (" ..." if len(few) > 40 else "") +
            " (metrics.csv `texel_f32_steps`, run.json `precision_limited`)."]


def write_table(path: Path, rows: list, name: str, source: str, status=None, oracle_rows=(), texels=(),
                state=None, planned=None, derived=()):
    """table.md: the answer first (dsm.report.summary), then failures, then every case, then the
    views at equal memory, the oracles and the frontier of error, bytes and rays. ``state`` and ``planned`` (run.json's
    state and the plan's case count) mark a run that stopped early; ``derived``: the lines saying what a
    run derived from its scene file (dsm.report.derivation), before the answer."""
    failed = sum(1 for x in status or [] if x["status"] == "failed")
    lines = [f"# {name}", "", *unfinished_md(state, planned, len(rows)), f"Config: `{source}`. {len(rows)} cases" +
             (f"; **{failed} failed** (see Failed below)" if failed else "") + ". Rates: acne = n_acne / n_gt_lit, "
             "peter-pan = n_peterpan / n_gt_shadowed, error = (acne + peter-pan) / receivers. "
             "A dash: undefined (an empty denominator), left out of every summary and plot. report.html shows "
             "the same with a sortable case table, the images and the plots.", "", *derived,
             *frontier.summary_md(frontier.points_from_rows(rows)), *summary.summary_md(rows), *status_md(status), *precision_md(rows), "", "## Cases", "",
             "self/edge: acne counts on the receiver's own surface / at another surface's outline; pp dist: median "
             "distance from a peter-panned receiver to its true occluder (world units). Times are medians over the "
             "timed repeats of the kernels' own time (Dr.Jit's kernel history).",
             "", legend_md(), "",
             "| case | " + " | ".join(h for _, h in TABLE_COLUMNS) + " |",
             "|---" * (len(TABLE_COLUMNS) + 1) + "|"]
    for r in rows:
        cells = [r["case"]] + [_cell(r.get(k)) for k, _ in TABLE_COLUMNS]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    lines += views_at_equal_memory(rows, texels)
    lines += soft_md(rows)
    lines += contact_report.contact_md(rows)
    lines += oracle_md(rows, list(oracle_rows or ()))
    lines += pareto_md(rows)
    with report_io.atomic(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def soft_rows(rows) -> list:
    """The rows of area-light cases (their soft metrics defined)."""
    return [r for r in rows if r.get("n_umbra", "") != "" and metrics.defined(r.get("n_umbra"))]


def soft_md(rows: list) -> list:
    """Area lights: V against the Monte Carlo V* by region (umbra V* = 0, penumbra, lit V* = 1),
    the reference's mean interval half-width (at its confidence), and each filter's lookup time."""
    soft = soft_rows(rows)
    if not soft:
        return []
    cols = [("scene", "scene"), ("light", "light"), ("scheme", "scheme"), ("filter", "filter"),
            ("n_umbra", "umbra"), ("n_penumbra", "penumbra"), ("n_lit", "lit"), ("mae_umbra", "MAE umbra"),
            ("mae_penumbra", "MAE penumbra"), ("mae_lit", "MAE lit"), ("rmse", "RMSE"), ("acne_rate", "acne"),
            ("peterpan_rate", "peter-pan"), ("ref_half_width_mean", "ref ±"), ("lookup_ms", "lookup ms")]
    lines = ["", "## Soft shadows (area lights)", "",
             "V against the reference V* (the visible fraction of the light, Monte Carlo): mean absolute error "
             "per region (umbra: no reference sample visible, lit: all, penumbra: the rest), RMSE over all "
             "receivers; acne over the lit receivers (V < 0.5), peter-pan over the umbra (V >= 0.5); ref ±: "
             "the reference's mean interval half-width at the light's confidence (default 99 %). Rays per receiver by region: run.json `reference_regions`. "
             "Images: images/<scene>_<light>/<case>_v.png, _vstar.png, _abserr.png; plots/soft_*.png.",
             "", "| case | " + " | ".join(h for _, h in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for r in soft:
        lines.append("| " + " | ".join(map(str, [r["case"]] + [_cell(r.get(k)) for k, _ in cols])) + " |")
    return lines


def case_time(r) -> float:
    """What a technique costs per frame: its map build plus its lookup (ms)."""
    return r["build_ms"] + r["lookup_ms"]


def pareto_md(rows: list) -> list:
    """table.md's frontier section: per scene and light, the cases on the frontier (dsm.report.frontier:
    no other case has at most their error rate, bytes and rays, one lower), cheapest first, times beside."""
    points = frontier.points_from_rows(rows)
    if not points:
        return []
    out = ["", "## What accuracy costs: the frontier", "",
           "Per scene and light: the cases no other case beats on error rate without reading more bytes or "
           "casting more rays (frontier.csv marks every case), over every scheme, resolution, view, filter and "
           "format; time is measured and shown (map build and lookup, kernel-time medians), never deciding. "
           "plots/pareto_*.png plot every case's error against its bytes with the frontier marked.", "",
           "| scene | light | instance | error rate | bytes | rays | taps | build ms | lookup ms |",
           "|---" * 9 + "|"]
    on = [p for p, m in zip(points, frontier.on_frontier(points)) if m]
    for p in sorted(on, key=lambda p: (p.scene, p.light, p.bytes, p.rays, p.error, p.instance)):
        out.append(f"| {p.scene} | {p.light} | {p.instance} | {p.error:.4f} | {frontier.size(p.bytes)} | "
                   f"{p.rays:,} | {p.taps:.3g} | {p.build_ms:.3g} | {p.lookup_ms:.3g} |")
    return out


def views_at_equal_memory(rows: list, budgets=()) -> list:
    """Markdown lines comparing the views of each point light, case by case, at equal texel budgets."""
    groups = {}
    for r in rows:
        budget = min(budgets, key=lambda b: abs(b - r["total_texels"])) if budgets else r["total_texels"]
        key = (r["scene"], r["light"], r["scheme"], r["params"], r["culling"], r["filter"], r["format"], budget)
        groups.setdefault(key, {})[r["view"]] = r
    views = sorted({v for g in groups.values() for v in g if len(g) > 1})
    if not views:
        return []
    out = ["", "## Views at equal memory", "",
           "Each view gets the same total texel budget (R = sqrt(texels / faces)). error: (acne + peter-pan) / "
           "receivers; seam: the error rate within 3 texels of a seam (cube edges, paraboloid rim) / elsewhere; "
           "time: build + lookup (ms). Best: the lowest error rate, then the shorter time.", "",
           "| scene | light | scheme | params | texels | " + " | ".join(f"{v} error | {v} seam | {v} time"
                                                             for v in views) + " | best |",
           "|---" * (5 + 3 * len(views) + 1) + "|"]
    for key, g in sorted(groups.items(), key=lambda kv: (tuple(map(str, kv[0][:7])), kv[0][7])):
        if len(g) < 2:
            continue
        cells = [key[0], key[1], key[2], key[3], key[7]]
        for v in views:
            r = g.get(v)
            cells += ([_cell(r["error_rate"]), f"{_cell(r['seam_error_rate'])} / {_cell(r['off_seam_error_rate'])}",
                       f"{case_time(r):.1f}"] if r else ["", "", ""])
        scored = [r for r in g.values() if metrics.defined(r["error_rate"])]
        if not scored:
            continue
        best = min(scored, key=lambda r: (round(r["error_rate"], 4), case_time(r)))
        out.append("| " + " | ".join(map(str, cells + [best["view"]])) + " |")
    return out


def _cell(x):
    if isinstance(x, float):
        if not metrics.defined(x):
            return "-"
        return f"{x:.4f}" if abs(x) < 10 else f"{x:.1f}"
    return x


# ------------------------------------------------------------------ run.json

def run_info(cfg, variant, rays, status, versions_: dict, threads: int) -> dict:
    """run.json's content: config, versions, variant, rays, case counts by status and every status."""
    failed = [s for s in status if s["status"] == "failed"]
    return {
        "experiment": cfg.name, "config_file": cfg.source, "config": cfg.raw, "versions": versions_,
        "variant": variant, "threads": threads, "timing_repeats": cfg.timing_repeats,
        "rays": dict(rays), "n_cases_ok": sum(1 for s in status if s["status"] == "ok" and s["what"].startswith("case")),
        "n_failed": len(failed), "n_skipped": sum(1 for s in status if s["status"] == "skipped"),
        "n_empty": sum(1 for s in status if s["status"] == "empty"),
        "n_warnings": sum(1 for s in status if s["status"] in ("warning", "note")), "status": status,
    }
