"""What dsm tune writes into its folder: tuned.toml, table.md, steps.csv, tune.json, bias_map.npy, plots."""
from __future__ import annotations

import csv
import dataclasses
from dataclasses import dataclass
import json
import math
from pathlib import Path

import numpy as np

from ..report.io import atomic
from ..core import env
from ..core.types import Length
from .compare import FINE, GRADCHECK_STEP
from .search import Param
from ..config.tune import TuneSpec


@dataclass
class TuneResult:
    """What ``dsm tune`` writes: per tuned scheme its values, hard metrics on the training and
    held-out views, the grid search and (constant) the oracle; the per-step rows; the learned
    bias map's result; the comparison rows."""
    schemes: list
    steps: list
    comparison: list
    bias_map: dict | None
    notes: list
    n_train: int
    n_heldout: int
    tuned_toml: str
    spec: TuneSpec
    resumed: int = 0      # schemes kept from the previous tune in the folder (--resume)
    moments: list = dataclasses.field(default_factory=list)    # pre-filtered instances tuned (dsm.tune.moments)

    def best(self):
        """The tuned scheme with the lowest training objective."""
        return min(self.schemes, key=lambda s: s["train"]["objective"]) if self.schemes else None


def tuned_toml(results) -> str:
    """The tuned instances as ready ``[[scheme]]`` blocks."""
    lines = ["# tuned by dsm tune: paste into an experiment config"]
    for e in results:
        lines.append("[[scheme]]")
        lines.append(f'name = "{e["scheme"]}"')
        for f in dataclasses.fields(e["spec"].params):
            v = getattr(e["spec"].params, f.name)
            if isinstance(v, Length):
                if not math.isfinite(v.value):
                    continue               # a default without a finite value (no clamp): left at its default
                lines.append(f'{f.name} = {v.value!r}' if v.unit == "world" else f'{f.name} = "{v.value!r} {v.unit}"')
            elif isinstance(v, float):
                lines.append(f"{f.name} = {v!r}")
            elif isinstance(v, str):
                lines.append(f'{f.name} = "{v}"')
        lines.append(f"# train objective {e['train']['objective']:.6f}")
        lines.append("")
    return "\n".join(lines)


def moments_toml(entries) -> str:
    """The tuned pre-filtered instances as ``[map.<kind>]`` tables, one per instance in comments
    (instances of one kind at other blur widths may want other values: paste the one you run)."""
    if not entries:
        return ""
    lines = ["", "# pre-filtered maps, tuned per instance (every parameter, the tuned ones exactly; a preset's "
             "values spelled out: uncomment the one you run)"]
    for e in entries:
        lines.append(f"# {e['label']}: train objective {e['train']:.6f}")
        lines.append(f"# [map.{e['kind']}]")
        lines += [f"# {k} = {v!r}" for k, v in e["all_values"].items()]
    return "\n".join(lines) + "\n"


def moments_table(res) -> list:
    """table.md's section of the tuned pre-filtered instances (empty without any)."""
    if not res.moments:
        return []
    floor = res.moments[0].get("depth_oracle_train")
    out = ["", "## pre-filtered maps (dsm.tune.moments; the exponents of ESM and EVSM searched exactly, the "
           "others by gradient)", ""]
    if floor:
        out += [f"the depth map's exact oracles on the training views: one world bias {_fmt(floor['world'])}, "
                f"per texel {_fmt(floor['per_texel'])} (an unfiltered VSM is a depth test with one bias in "
                "normalized depth per map: on one map its best is the world oracle)", ""]
    out += [
           "| instance | tuned | train | held-out | tune ms | grid best | grid train | grid held-out (evals) "
           "| start train | start held-out | AD / central difference (relative error) |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    above = [e["label"] for e in res.moments if e["train"] > e["grid"]["train"]]
    for e in res.moments:
        g = e["grid"]
        check = ", ".join(f"{k} {_fmt(c['rel_error'])}" for k, c in (e.get("gradcheck") or {}).items())
        out.append(f"| {e['label']} | {e['params']} | {_fmt(e['train'])} | {_fmt(e['heldout'])} | {e['tune_ms']:.0f} "
                   f"| {g['params']} | {_fmt(g['train'])} | {_fmt(g['heldout'])} ({g['evaluations']}) "
                   f"| {_fmt(e['start_train'])} | {_fmt(e['start_heldout'])} | {check} |")
    if above:       # the search is held to its grid, not guaranteed below it: say where it is not
        out += ["", f"above its grid (the search's share of {res.spec.steps} evaluations found less than a grid of "
                f"all of them; more steps): {', '.join(above)}"]
    return out


# ---------------------------------------------------------------- output folder

def _sides(g: dict) -> str:
    """A gradient check's one-sided differences, and *kink* where they disagree (compare.differences)."""
    if "left" not in g:
        return "-"
    return f"{g['left']:.6g} / {g['right']:.6g}" + (" *kink*" if g.get("kink") else "")


def _fine(g: dict) -> str:
    """A gradient check's central difference at a quarter of the step and its relative error."""
    if "fd_fine" not in g:
        return "- | -"
    return f"{g['fd_fine']:.6g} | {_fmt(g['rel_error_fine'])}"


def _fmt(x):
    if isinstance(x, float):
        return "-" if math.isnan(x) else f"{x:.5f}"
    return str(x)


def _fmt2(x: float) -> str:
    """A ratio to two decimals, "-" where undefined."""
    return "-" if math.isnan(x) else f"{x:.2f}"


def _bias_map_head(b: dict) -> str:
    """table.md's sentence on the learned bias map: its fit, what it is over, its coverage."""
    if b.get("fit") == "residual":
        how = (f"a residual in texels over {b['base']}, blocks of {b['block']} x {b['block']} texels fitted "
               f"exactly to the training receivers of the blocks within {b['radius']} of each, moved where they "
               f"gain at least {b['min_gain']} errors ({b['blocks_moved']} of {b['blocks']} blocks moved)"
               if b["chosen"] else f"no residual over {b['base']}: no candidate (block, radius, min_gain) "
               f"beat it leaving one training camera out ({b['validation']['none']:g} errors; best candidate "
               f"{min((s['errors'] for s in b['validation']['scores']), default=float('nan')):g})")
        return f"{how}; {_fmt(b['heldout_covered_fraction'])} of held-out receivers fall in trained blocks"
    elif b.get("fit") == "edge":
        m = b["model"]
        return (f"an edge map over {b['base']}: lit where the tent (half-width {m['width']:g} texel) mean of the "
                f"3 x 3 taps' margins clipped at {m['clip']:g} texel is at least {m['threshold']:.4g} + "
                f"{m['grazing']:g} (1 - cos){_offsets_clause(b)}, fitted exactly to the training receivers "
                f"({len(b['candidates'])} candidates); {_fmt(b['heldout_covered_fraction'])} of held-out receivers "
                f"fall in {b['block']} x {b['block']} blocks with training receivers")
    else:
        return (f"{b['blocks']} blocks of {b['block']} x {b['block']} texels ({b['blocks_trained']} with training "
                f"receivers; {_fmt(b['heldout_covered_fraction'])} of held-out receivers fall in them), unit "
                f"{b['unit']}, started from {b['init_from']} (per map: "
                f"{', '.join(f'{x:.4g}' for x in b['init'])})")


def _offsets_clause(b: dict) -> str:
    """table.md's words on an edge map's per-texel offsets (light samples), with the training cameras' check."""
    o = b.get("offsets")
    if not o:
        return " (no per-texel offsets: samples = 0)"
    if not o["n_samples"]:
        return f" (no per-texel offsets: {o['note'] or 'no light sample fell in the maps'})"
    errors = lambda c: c["n_acne"] + c["n_peterpan"]
    n = lambda k, word: f"{k} {word}{'s' * (k != 1)}"
    return (f" minus a per-texel offset fitted exactly to {n(o['n_samples'], 'light sample')} ({o['samples']} x "
            f"{o['samples']} rays a texel, up to {n(o['layers'], 'surface')} each; {o['n_shadowed']} in shadow; "
            f"{o['texels_moved']} of {n(o['texels'], 'texel')} moved; {o['ms'] / 1e3:.1f} s), which no camera sees: "
            f"on the training cameras {n(errors(b['train']), 'error')} with the offsets, "
            f"{errors(b['train_shared'])} without{'; ' + o['note'] if o['note'] else ''})")


def table_text(res: TuneResult) -> str:
    """The Markdown summary (``table.md``): a row per tuned scheme against grid search and oracle, then the bias map."""
    out = [f"# dsm tune (lambda = {res.spec.lam:g}; objective (n_acne + lambda n_peterpan) / n_receivers)", "",
           f"training receivers {res.n_train}, held-out receivers {res.n_heldout}"]
    out += _scheme_section(res) + _blackbox_section(res) + _gradcheck_section(res)
    if res.bias_map:
        out += _bias_map_section(res.bias_map)
    out += moments_table(res)
    if res.notes:
        out += ["", "notes: " + "; ".join(res.notes)]
    return "\n".join(out) + "\n"


def _scheme_section(res: TuneResult) -> list:
    """table.md's row per tuned scheme (tuned, grid, oracle, start, scan) and the note on one-point grids."""
    out = []
    if res.comparison:             # a tune of pre-filtered instances alone has no scheme table
        out += ["", "| scheme | tuned | train | held-out | tune ms (evals; first, median step) | grid best | grid train "
           "| grid held-out | grid ms (evals) | oracle (train) | start train | start held-out | 1-D scan best "
           "| scan train (evals) | tuned / scan |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in res.comparison:
        out.append(f"| {r['scheme']} | {r['tuned_params']} | {_fmt(r['tuned_train'])} | {_fmt(r['tuned_heldout'])} "
                   f"| {r['tuned_ms']:.0f} ({r['tuned_evaluations']}; {r['first_step_ms']:.1f}, {r['step_ms']:.1f}) "
                   f"| {r['grid_params']} | {_fmt(r['grid_train'])} "
                   f"| {_fmt(r['grid_heldout'])} | {r['grid_ms']:.0f} ({r['grid_evaluations']}) "
                   f"| {_fmt(r['oracle'])} | {_fmt(r['start_train'])} | {_fmt(r['start_heldout'])} "
                   f"| {r['scan_params']} | {_fmt(r['scan_train'])} ({r['scan_evaluations']}) "
                   f"| {_fmt(r['tuned_train'] / r['scan_train']) if r['scan_train'] > 0 else '-'} |")
    thin = [e["scheme"] for e in res.schemes if (e.get("grid") or {}).get("points_per_parameter", 2) < 2]
    if thin:        # a grid of one point (the box's centre) compares nothing
        out += ["", f"a grid of one point per parameter (steps {res.spec.steps} < 2^parameters; its box's centre): "
                f"{', '.join(thin)}: give more steps for a comparison"]
    return out


def _blackbox_section(res: TuneResult) -> list:
    """table.md's AD tuner against Optuna's TPE at equal exact evaluations, and NSGA-II's front (search = optuna)."""
    rows = [r for r in res.comparison if "optuna_train" in r]
    if not rows:
        return []
    out = ["", "AD against Optuna's TPE at the same number of exact evaluations (the objective on the training "
           "views; evaluations: exact / relaxed passes / exact line searches):", "",
           "| scheme | AD | AD train | AD held-out | AD evaluations | AD wall ms (CPU ms) | TPE | TPE train "
           "| TPE held-out | TPE evaluations | TPE wall ms (CPU ms) | lower on train |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        out.append(f"| {r['scheme']} | {r['tuned_params']} | {_fmt(r['tuned_train'])} | {_fmt(r['tuned_heldout'])} "
                   f"| {r['tuned_evaluations']} / {r['tuned_relaxed_evaluations']} / {r['tuned_line_searches']} "
                   f"| {r['tuned_wall_ms']:.0f} ({r['tuned_cpu_ms']:.0f}) | {r['optuna_params']} "
                   f"| {_fmt(r['optuna_train'])} | {_fmt(r['optuna_heldout'])} | {r['optuna_evaluations']} / 0 / 0 "
                   f"| {r['optuna_wall_ms']:.0f} ({r['optuna_cpu_ms']:.0f}) "
                   f"| {lower_words(r['tuned_train'], r['optuna_train'])} |")
    for e in res.schemes:
        f = e.get("optuna_front")
        if f:
            ad = f["ad_point"]
            pts = ", ".join(f"({p['acne_per_receiver']:.5f}, {p['peterpan_per_receiver']:.5f})" for p in f["front"])
            out += ["", f"{e['scheme']} {e['start']}: NSGA-II's Pareto front in (acne, peter-panning) per receiver "
                    f"({f['trials']} trials, population {f['population']}): {pts}; the AD tuner's point at lambda "
                    f"{ad['lambda']:g}: ({ad['acne_per_receiver']:.5f}, {ad['peterpan_per_receiver']:.5f}), "
                    + ("dominated by the front" if ad["dominated"] else "on or beyond the front")]
    return out


def lower_words(ad: float, tpe: float) -> str:
    """Which search ended lower on the training objective: AD, TPE or a tie (equal objectives)."""
    if not (math.isfinite(ad) and math.isfinite(tpe)):
        return "undefined"
    return "tie" if ad == tpe else "AD" if ad < tpe else "TPE"


def _gradcheck_section(res: TuneResult) -> list:
    """table.md's gradient check: AD against central differences at two steps, per scheme and parameter."""
    checks = [(e["scheme"], k, g) for e in res.schemes for k, g in (e.get("gradcheck") or {}).items()]
    if not checks:
        return []
    out = ["", f"## gradient check (relaxed loss at the start, temperature {res.spec.temperature[0]:g} texel; "
           f"central difference, half step {GRADCHECK_STEP:g} texel's worth, numpy float64)", "",
           "| scheme | parameter | AD | central difference | relative error | left / right difference "
           f"| central, step / {FINE} | relative error |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    out += [f"| {n} | {k} | {g['ad']:.6g} | {g['fd']:.6g} | {_fmt(g['rel_error'])} | {_sides(g)} "
            f"| {_fine(g)} |" for n, k, g in checks]
    out += ["", f"*central, step / {FINE}*: the same difference at a quarter of the step. Where the loss sums "
            "receivers that each bend somewhere (a bilinear z1 bends at texel centres), a step straddles fewer "
            "bends as it shrinks, so an error that falls with the step is the difference's, not AD's."]
    if any(g.get("kink") for _, _, g in checks):
        out += ["", "*kink*: the one-sided differences disagree, so the loss bends within the step (a max or a "
                "clamp of the scheme) and the central difference averages two slopes: its disagreement there is no "
                "evidence against AD."]
    return out


def _bias_map_section(b: dict) -> list:
    """table.md's learned bias map: its train and held-out objectives beside the oracle and the best global
    scheme, and the held-out split by trained blocks."""
    bg = b["best_global"]
    out = ["", "## learned bias map", "", _bias_map_head(b), "",
           "| | train | held-out |", "| --- | --- | --- |",
           f"| learned map | {_fmt(b['train']['objective'])} | {_fmt(b['heldout']['objective'])} |",
           f"| per-texel oracle (of those views) | {_fmt(b['per_texel_oracle_train'])} "
           f"| {_fmt(b['per_texel_oracle_heldout'])} |"]
    if bg:
        out.append(f"| best tuned global ({bg['scheme']} {bg['params']}) | {_fmt(bg['train'])} "
                   f"| {_fmt(bg['heldout'])} |")
    if b.get("heldout_split"):
        out += _split_table(b["heldout_split"])
    return out


def _split_table(split: dict) -> list:
    """table.md's held-out split by trained blocks, with the edge map's refits where it has them."""
    refit = all("refit" in r for r in split.values())
    shared = all("shared_map" in r for r in split.values())
    extra = ((" family refitted to them (in-sample) | its gap closed | cross-fitted by halves | its gap closed |",
              " --- | --- | --- | --- |") if refit else ("", ""))
    mid = (" shared threshold (no offsets) | its gap closed |", " --- | --- |") if shared else ("", "")
    out = ["", "| held-out receivers | n | per texel | learned map | best tuned global | per-texel oracle "
           "| gap closed |" + mid[0] + extra[0], "| --- | --- | --- | --- | --- | --- | --- |" + mid[1] + extra[1]]
    for name, r in split.items():
        row = (f"| in {'trained' if name == 'covered' else 'untrained'} blocks | {r['n_receivers']} "
               f"| {_fmt2(r.get('receivers_per_texel', math.nan))} | {_fmt(r['map'])} | {_fmt(r['best_global'])} "
               f"| {_fmt(r['per_texel_oracle'])} | {_fmt(r['gap_closed'])} |")
        row += f" {_fmt(r['shared_map'])} | {_fmt(r['shared_gap_closed'])} |" if shared else ""
        out.append(row + (f" {_fmt(r['refit'])} | {_fmt(r['refit_gap_closed'])} | {_fmt(r['crossfit'])} "
                          f"| {_fmt(r['crossfit_gap_closed'])} |" if refit else ""))
    out += ["", "*per texel*: receivers per map texel they fall in. The per-texel oracle gives each texel "
            "its best bias for those very receivers, so with about one receiver a texel it classifies nearly "
            "every receiver right and the gap is widest; the gap closed depends on it."]
    if shared:
        out += ["", "*trained blocks* are the training cameras'; the per-texel offsets are fitted to light samples, "
                "which reach every texel the light sees. The oracle is the best constant bias a texel, and an offset "
                "moves a threshold on a score that varies inside the texel, so the map may pass the oracle "
                "(a gap closed above 1)."]
    if refit:
        out += ["", "*in-sample*: the edge map's candidates, each with its exact threshold, fitted and counted on "
                "those very held-out receivers: the fewest errors any one map of the family makes there, an "
                "optimistic bound (it is scored on what it was fitted to). *cross-fitted*: the same fit on the "
                "receivers of half their texels (by a fixed hash of each texel), counted on the other half, and "
                "the other way round, averaged over four such halvings: what the family reaches with data "
                "from the judged views themselves. "
                "Where the learned map is near the cross-fitted figure, more training views would not help: "
                "the rest of the gap is the family's (its 3 x 3 taps, its candidate grid)."]
    return out


def write(res: TuneResult, out: Path, orc_train=None, orc_held=None):
    """Write ``res`` into folder ``out``: tuned.toml, steps.csv, table.md, tune.json (with the versions the
    tune ran on), bias_map.npy and the plots."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "tuned.toml").write_text(res.tuned_toml)
    keys = []
    for r in res.steps:
        keys += [k for k in r if k not in keys]
    with open(out / "steps.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys, restval="")
        w.writeheader()
        for r in res.steps:
            w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    (out / "table.md").write_text(table_text(res))
    doc = {"versions": env.versions(), "lambda": res.spec.lam, "n_train": res.n_train, "n_heldout": res.n_heldout, "notes": res.notes,
           "schemes": [{k: v for k, v in e.items() if k not in ("spec",)} for e in res.schemes],
           "comparison": res.comparison, "oracle_train": orc_train, "oracle_heldout": orc_held,
           "moments": res.moments,
           "bias_map": None if res.bias_map is None else
           {k: v for k, v in res.bias_map.items() if k not in ("steps", "values", "texel_offsets")}}
    if res.bias_map is not None:
        np.save(out / "bias_map.npy", res.bias_map["values"])
        if res.bias_map.get("texel_offsets") is not None:      # rows: texel key (residual_map.block_keys), offset
            np.save(out / "texel_offsets.npy", res.bias_map["texel_offsets"])
    (out / "tune.json").write_text(json.dumps(_no_nan(doc), indent=1, default=_json_default))
    plot(res, out / "plots")


def _no_nan(o):
    """Undefined values (NaN) as JSON null."""
    if isinstance(o, dict):
        return {str(k): _no_nan(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_no_nan(v) for v in o]
    if isinstance(o, Param):
        return _no_nan(dataclasses.asdict(o))
    if isinstance(o, (float, np.floating)):
        return None if math.isnan(o) else float(o)
    return o


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def plot(res: TuneResult, folder: Path):
    """Plot each scheme instance's relaxed loss and hard objective per step into ``folder``/tune_loss.png
    (on a Figure of its own: no pyplot, so a notebook's backend stays as it is)."""
    from matplotlib.figure import Figure
    folder.mkdir(parents=True, exist_ok=True)
    label = lambda r: r.get("instance") or r["scheme"]
    fig = Figure(figsize=(10, 3.6))
    axes = fig.subplots(1, 2)
    for name in dict.fromkeys(label(r) for r in res.steps):
        rows = [r for r in res.steps if label(r) == name]
        s = [r["step"] for r in rows]
        axes[0].plot(s, [r["loss"] for r in rows], label=name[:48])
        axes[1].plot(s, [r["hard_objective"] for r in rows], label=name[:48])
    axes[0].set(title="relaxed loss", xlabel="step")
    axes[1].set(title=f"hard objective (lambda = {res.spec.lam:g})", xlabel="step")
    axes[1].legend(fontsize=6)
    fig.tight_layout()
    with atomic(folder / "tune_loss.png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
