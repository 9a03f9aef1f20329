"""Report: metrics.csv (written row by row), table.md, images/, plots/, run.json."""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np

from . import metrics

COLUMNS = [
    "case", "scene", "light", "view", "scheme", "preset", "params", "culling", "resolution", "total_texels", "filter", "format",
    "cascade_layout",
    "n_pixels", "n_excluded_nohit", "n_excluded_backfacing", "n_excluded_outside",
    "n_receivers", "n_gt_lit", "n_gt_shadowed", "n_acne", "n_acne_self", "n_acne_edge", "n_peterpan",
    "n_acne_resolution", "n_acne_bias", "n_peterpan_resolution", "n_peterpan_bias",
    "acne_rate", "peterpan_rate", "error_rate", "mean_abs_error", "peterpan_dist_median",
    "n_seam", "seam_error_rate", "off_seam_error_rate", "texel_size", "texels_per_pixel", "fit_ms", "n_plane_fallback",
    "n_backfacing", "backface_lit_rate",
    "build_ms", "build_first_ms", "build_compile_ms", "build_peak_mb", "lookup_ms", "lookup_compile_ms", "lookup_kernels_compiled", "reference_ms",
    "sweep_key", "sweep_value",
]


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


def write_json(path: Path, data: dict, indent=None):
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
        with open(self.path, "a", newline="") as fh:
            csv.writer(fh).writerow([_fmt(row.get(c, "")) for c in COLUMNS])


def _fmt(x):
    if isinstance(x, float):
        return f"{x:.6g}" if metrics.defined(x) else ""      # undefined: an empty cell
    return x


def read_csv(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def progress(total: int, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, unit="case", disable=not enabled or not sys.stderr.isatty(), dynamic_ncols=True)


def sweep_of(spec, all_specs) -> tuple[str, float]:
    """The numeric parameter a scheme's sweep varies (or its first one) and this case's value of it."""
    fields = [f.name for f in dataclasses.fields(spec.params)
              if isinstance(getattr(spec.params, f.name), (int, float)) or hasattr(getattr(spec.params, f.name), "unit")]
    if not fields:
        return "", 0.0
    siblings = [s.params for s in all_specs if s.name == spec.name and s.preset is None]
    key = next((k for k in fields if len({getattr(p, k) for p in siblings}) > 1), fields[0])
    val = getattr(spec.params, key)
    unit = getattr(val, "unit", "")
    return (f"{key} [{unit}]" if unit else key), float(getattr(val, "value", val))


# ------------------------------------------------------------------ images

def write_case_images(folder: Path, case: str, classes: np.ndarray, gb, setup, v: np.ndarray):
    """The error image (one colour per class) and the shadow-mapped render of one case."""
    from matplotlib.image import imsave
    save_png(folder / f"{case}_error.png", lambda f, fmt: imsave(f, metrics.CLASS_COLORS[classes], format=fmt))
    # Lambert under the light with the map's visibility, ambient elsewhere.
    shade = np.zeros(gb.width * gb.height)
    shade[gb.hit] = 0.12
    if setup.n is not None:
        n = np.stack([c.numpy() for c in (setup.n.x, setup.n.y, setup.n.z)], 1)
        to_light = _to_light_np(setup, n.shape[0])
        shade[setup.pixels] = 0.12 + 0.88 * np.clip((n * to_light).sum(1), 0, 1) * v
    save_png(folder / f"{case}_shadow.png", lambda f, fmt: imsave(f, shade.reshape(gb.height, gb.width), cmap="gray",
                                                                  vmin=0, vmax=1, format=fmt))


def _to_light_np(setup, count):
    light = setup.light
    if light.type == "directional":
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
    items = [f"{name}: rgb{tuple(int(c) for c in col)}" for name, col in zip(metrics.CLASS_NAMES, metrics.CLASS_COLORS)]
    return "Error images (`images/<case>_error.png`): " + "; ".join(items) + "."


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
    """oracle.csv: one row per map, stored format and lambda (written atomically)."""
    with atomic(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(ORACLE_COLUMNS)
            for r in rows:
                w.writerow([_fmt(r.get(c, "")) for c in ORACLE_COLUMNS])


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
    for key, o in orc.items():
        rs = [r for r in near if _map_key(r) == key]
        bc = min(rs, key=lambda r: objective(r, lam)) if rs else None
        out.append(f"| {' | '.join(map(str, key))} | {o['best_b']:.4g} | {_cell(o['world_objective'])} | "
                   f"{o['best_k']:.4g} | {_cell(o['texel_objective'])} | {_cell(o['per_texel_objective'])} | "
                   + (f"{bc['scheme']} {bc['preset'] or bc['params']} | {objective(bc, lam):.4f} |" if bc else "- | - |"))
    return out


def write_tradeoff(folder: Path, rows: list, curves: list, lam: float = 1.0):
    """Per scene, light and view: peter-panning rate against acne rate, each map's exact oracle
    curve (one world bias for the map) as a line and each nearest-filter case as a point."""
    from matplotlib.figure import Figure
    if not curves:
        return
    folder.mkdir(exist_ok=True)
    groups = {}
    for row, cw, ck in curves:
        groups.setdefault((row["scene"], row["light"], row["view"]), []).append((row, cw, ck))
    for (scene, light, view), cs in sorted(groups.items()):
        cs = [c for c in cs if c[1].n_lit and c[1].n_shadowed]     # both rates defined
        if not cs:
            continue
        fig = Figure(figsize=(8.5, 4.6))
        ax = fig.subplots()
        for k, (row, cw, ck) in enumerate(cs):
            lab = f"oracle R={row['resolution']} {row['format']}" + (f" {row['culling']}" if row["culling"] != "none" else "")
            ax.step(cw.acne / cw.n_lit, cw.peterpan / cw.n_shadowed, where="post", color=f"C{k % 10}", lw=1.0,
                    label=lab + " (world b)")
            ax.step(ck.acne / ck.n_lit, ck.peterpan / ck.n_shadowed, where="post", color=f"C{k % 10}", lw=0.8,
                    ls=":", label=lab + " (k texel)")
            pts = [r for r in rows if r["filter"] == "nearest" and (r["scene"], r["light"], r["view"]) ==
                   (scene, light, view) and _map_key(r) == _map_key(row) and metrics.defined(r["acne_rate"])
                   and metrics.defined(r["peterpan_rate"])]
            ax.scatter([r["acne_rate"] for r in pts], [r["peterpan_rate"] for r in pts], s=14, color=f"C{k % 10}",
                       edgecolors="k", linewidths=0.3)
        ax.set_xscale("symlog", linthresh=1e-3)
        ax.set_yscale("symlog", linthresh=1e-3)
        ax.set_xlabel("acne rate")
        ax.set_ylabel("peter-panning rate")
        ax.set_title(f"{scene}, light {light}, {view}: exact trade-off of one bias (lines), cases (points)", fontsize=9)
        fig.subplots_adjust(left=0.1, right=0.68, bottom=0.12, top=0.9)
        ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=6, frameon=False)
        save_png(folder / f"tradeoff_{_slug(f'{scene}_{light}_{view}')}.png",
                 lambda f, fmt: fig.savefig(f, dpi=80, format=fmt))


def write_table(path: Path, rows: list, cfg, status=None, oracle_rows=()):
    lines = [f"# {cfg.name}", "", f"Config: `{cfg.source}`. {len(rows)} cases. Rates: acne = n_acne / n_gt_lit, "
             "peter-pan = n_peterpan / n_gt_shadowed, error = (acne + peter-pan) / receivers; "
             "self/edge: acne counts on the receiver's own shape / at another shape's edge; pp dist: median "
             "distance from a peter-panned receiver to its true occluder (world units). Times are warm medians. "
             "A dash: undefined (an empty denominator), left out of every summary and plot.",
             *status_md(status), "", legend_md(), "",
             "| case | " + " | ".join(h for _, h in TABLE_COLUMNS) + " |",
             "|---" * (len(TABLE_COLUMNS) + 1) + "|"]
    for r in rows:
        cells = [r["case"]] + [_cell(r.get(k)) for k, _ in TABLE_COLUMNS]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    lines += views_at_equal_memory(rows, getattr(cfg.map, "texels", ()))
    lines += oracle_md(rows, list(oracle_rows or ()))
    lines += pareto_md(rows)
    with atomic(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def case_time(r) -> float:
    """What a technique costs per frame: its map build plus its lookup (ms)."""
    return r["build_ms"] + r["lookup_ms"]


def pareto_front(rows: list) -> list:
    """The rows no other row beats on both error rate and time (ties kept once), fastest first."""
    pts = sorted((r for r in rows if metrics.defined(r["error_rate"])), key=lambda r: (case_time(r), r["error_rate"]))
    front, best = [], float("inf")
    for r in pts:
        if r["error_rate"] < best:
            front.append(r)
            best = r["error_rate"]
    return front


def _pareto_groups(rows):
    groups = {}
    for r in rows:
        groups.setdefault((r["scene"], r["light"], r["view"]), []).append(r)
    return sorted(groups.items())


def pareto_md(rows: list) -> list:
    if not rows:
        return []
    out = ["", "## Cost of accuracy: the Pareto frontier", "",
           "Per scene, light and view: the cases no other case beats on both error rate and time "
           "(map build + lookup, warm medians), over every scheme, resolution, filter and format. "
           "plots/pareto_*.png plots all cases with the frontier marked.", "",
           "| scene | light | view | scheme | params | R | filter | format | error rate | time ms |",
           "|---" * 10 + "|"]
    for (scene, light, view), rs in _pareto_groups(rows):
        for r in pareto_front(rs):
            out.append(f"| {scene} | {light} | {view} | {r['scheme']} | {r['params']} | {r['resolution']} | "
                       f"{r['filter']} | {r['format']} | {r['error_rate']:.4f} | {case_time(r):.2f} |")
    return out


def write_pareto(folder: Path, rows: list):
    from matplotlib.figure import Figure     # no pyplot: a notebook's backend stays as it is
    folder.mkdir(exist_ok=True)
    for (scene, light, view), rs in _pareto_groups(rows):
        rs = [r for r in rs if metrics.defined(r["error_rate"])]     # empty cases have no error rate
        if not rs:
            continue
        schemes = sorted({r["scheme"] for r in rs})
        fig = Figure(figsize=(8.5, 4.2))
        ax = fig.subplots()
        for k, s in enumerate(schemes):
            pts = [(case_time(r), r["error_rate"]) for r in rs if r["scheme"] == s and metrics.defined(r["error_rate"])]
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=14, color=f"C{k % 10}", label=s)
        front = pareto_front(rs)
        ax.plot([case_time(r) for r in front], [r["error_rate"] for r in front], "k-", lw=0.8)
        ax.scatter([case_time(r) for r in front], [r["error_rate"] for r in front], s=60, facecolors="none",
                   edgecolors="k", label="non-dominated")
        ax.set_xscale("log")
        ax.set_xlabel("time per case: map build + lookup (ms)")
        ax.set_ylabel("error rate (acne + peter-panning) / receivers")
        ax.set_title(f"{scene}, light {light}, {view}", fontsize=9)
        fig.subplots_adjust(left=0.09, right=0.72, bottom=0.13, top=0.9)
        ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=7, frameon=False)
        save_png(folder / f"pareto_{_slug(f'{scene}_{light}_{view}')}.png", lambda f, fmt: fig.savefig(f, dpi=80, format=fmt))


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


# ------------------------------------------------------------------ plots

def _panels(path, series: dict, xlabel: str, ylabels: tuple, title: str, xlog: bool = False, style="o-",
            styles=None):
    """One figure with a panel per y quantity; ``series``: label -> [(x, y0, y1, ...)];
    ``styles``: label -> extra plot keywords (colour, line style)."""
    from matplotlib.figure import Figure
    # undefined values (NaN: an empty denominator) are left out, not drawn as 0
    series = {k: sorted(p for p in v if any(metrics.defined(float(y)) for y in p[1:])) for k, v in series.items()}
    series = {k: v for k, v in series.items() if v}
    if not series:
        return
    n = len(ylabels)
    fig = Figure(figsize=(4.6 * n + 3.4, 3.8))
    axes = fig.subplots(1, n)
    for label, pts in series.items():
        for k, ax in enumerate(axes, start=1):
            ax.plot([p[0] for p in pts], [p[k] for p in pts], style, lw=0.9, label=label,
                    **(styles or {}).get(label, {}))
    for ax, what in zip(axes, ylabels):
        if xlog:
            ax.set_xscale("log", base=2)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(what)
    fig.suptitle(title, fontsize=9)
    # one legend beside the panels and fixed margins: tight_layout costs more than the drawing
    right = 4.6 * n / (4.6 * n + 3.4)
    fig.subplots_adjust(left=0.07 * 4.6 * n / (4.6 * n + 3.4), right=right - 0.01, bottom=0.13, top=0.88, wspace=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(right, 0.5), fontsize=6, frameon=False)
    save_png(path, lambda f, fmt: fig.savefig(f, dpi=80, format=fmt))


def write_plots(folder: Path, rows: list):
    """Per scene and light: error rates against the swept parameter and against resolution
    (per view), and, where a light was mapped with several views, error against the total
    texel count of each view (the equal-memory comparison)."""
    if not rows:
        return
    folder.mkdir(exist_ok=True)
    groups = {}
    for r in rows:
        groups.setdefault((r["scene"], r["light"]), []).append(r)
    rates = ("acne rate", "peter-panning rate")
    for (scene, light), rs in sorted(groups.items()):
        views = sorted({r["view"] for r in rs})
        for view in views:
            vr = [r for r in rs if r["view"] == view]
            tag = _slug(f"{scene}_{light}" + (f"_{view}" if len(views) > 1 else ""))
            rmax = max(r["resolution"] for r in vr)
            bias = {}
            for r in vr:
                if r["resolution"] == rmax and not r["preset"]:
                    lab = f"{r['scheme']} ({r['sweep_key']})" if r["sweep_key"] else r["scheme"]
                    bias.setdefault(lab, []).append((r["sweep_value"], r["acne_rate"], r["peterpan_rate"]))
            _panels(folder / f"vs_bias_{tag}.png", {k: v for k, v in bias.items()},
                    "swept parameter value (its unit in the legend)", rates, f"{scene}, light {light}, {view}, R={rmax}")
            res = {}
            for r in vr:
                res.setdefault(f"{r['scheme']} {r['params']}", []).append(
                    (r["resolution"], r["acne_rate"], r["peterpan_rate"]))
            _panels(folder / f"vs_resolution_{tag}.png", {k: v for k, v in res.items() if len(v) > 1},
                    "map resolution R (R x R texels per face)", rates, f"{scene}, light {light}, {view}", True, ".-")
        if len(views) > 1:
            tex, styles = {}, {}
            cases = sorted({(r["scheme"], r["params"]) for r in rs})
            for r in rs:
                lab = f"{r['view']}: {r['scheme']} {r['params']}"
                tex.setdefault(lab, []).append((r["total_texels"], r["error_rate"], r["seam_error_rate"]))
                styles[lab] = {"color": f"C{cases.index((r['scheme'], r['params'])) % 10}",
                               "linestyle": ("-", "--", ":", "-.")[views.index(r["view"]) % 4]}
            _panels(folder / f"vs_texels_{_slug(f'{scene}_{light}')}.png", tex, "total texels of the view (all faces)",
                    ("error rate", f"error rate within {metrics.SEAM_TEXELS:g} texels of a seam"),
                    f"{scene}, light {light}: views at equal memory (colour: scheme, line: view)", True, ".", styles)


def _slug(s: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in s)


# ------------------------------------------------------------------ run.json

def run_info(cfg, variant, rays, status, versions_: dict, threads: int) -> dict:
    failed = [s for s in status if s["status"] == "failed"]
    return {
        "experiment": cfg.name, "config_file": cfg.source, "config": cfg.raw, "versions": versions_,
        "variant": variant, "threads": threads, "timing_repeats": cfg.timing_repeats,
        "rays": dict(rays), "n_cases_ok": sum(1 for s in status if s["status"] == "ok" and s["what"].startswith("case")),
        "n_failed": len(failed), "n_skipped": sum(1 for s in status if s["status"] == "skipped"),
        "n_empty": sum(1 for s in status if s["status"] == "empty"),
        "n_warnings": sum(1 for s in status if s["status"] in ("warning", "note")), "status": status,
    }
