"""``dsm grad CONFIG``: the self-check table of a config's ``[gradient]`` table.

Writes ``selfcheck.csv`` (one row per technique and parameter, every number as Python's repr:
exact to paste back) and ``table.md`` (the same, rounded for reading) into ``--out``, and prints
the table. A relative error whose reference is 0 is undefined and shown as such, never as 0.
After the measuring: ``report.html`` (dsm.grad.page) and ``grad.json`` (the run's record: the
measuring's and the report's seconds apart).
"""
from __future__ import annotations

import csv
import dataclasses
import sys
import time
from pathlib import Path

from ..core import env
from ..experiment.lock import claim, entries, unwritable
from ..core.types import VARIANTS, ConfigError
from ..report.io import atomic, write_json, write_text
from . import spec as specmod
from . import compare as comparemod
from . import equal_error, figure, inverse, page, projective, tables
from .check import loss_unit, self_check
from .problem import Problem

COLUMNS = ("technique", "param", "unit", "loss", "ad", "fd", "fd_step", "changed_texels", "changed_pixels",
           "changed_pairs", "ad_vs_fd", "closed_form", "ad_vs_closed", "edge_pairs")


def add_parser(sub):
    """Add the ``grad`` subcommand to an argparse subparsers object."""
    g = sub.add_parser("grad", help="gradients of the shadowed image in scene parameters, per technique: AD "
                       "against central differences and closed forms (a config's [gradient])")
    g.add_argument("config", help="TOML file with a [gradient] table")
    g.add_argument("--out", default="grad", help="folder for selfcheck.csv, table.md, report.html and grad.json "
                   "(default: grad/)")
    g.add_argument("--variant", choices=VARIANTS, help="Mitsuba variant (default llvm_ad_rgb)")
    g.add_argument("--compare", action="store_true", help="also each technique against the supersampled exact "
                   "difference and Mitsuba's projective integrators: compare.csv, projective.csv, compare.md, "
                   "gradients.png")
    g.add_argument("--inverse", action="store_true", help="also the inverse task (recover each parameter by "
                   "descent through each technique): inverse.csv, inverse.md")
    g.add_argument("--force", action="store_true", help="replace the files an earlier dsm grad wrote in --out")
    return g


WRITTEN = ("selfcheck.csv", "table.md", "compare.csv", "projective.csv", "compare.md", "gradients.png",
           "equal_error.csv", "equal_error_curve.csv", "equal_error.png", "inverse.csv", "inverse.md",
           "relative_error.png", "inverse.png", "report.html", "grad.json")
MARKS = ("selfcheck.csv", "grad.json")      # what tells an earlier dsm grad's folder: its first and last file


def folder_problem(out: Path, force: bool) -> str | None:
    """Why dsm grad may not write into ``out`` (None if it may): a folder holding anything is refused
    unless --force and it holds an earlier dsm grad's files (its selfcheck.csv or grad.json: another
    command's report.html and table.md are not dsm grad's to replace); --force removes only the files
    dsm grad writes (WRITTEN, and their temporary files a killed run left; a user's own stay)."""
    held = entries(out) or []
    if not held:
        return unwritable(out)
    if not force:
        return (f"--out {out}: holds {len(held)} entries (an earlier run's?); --force replaces what dsm grad "
                "wrote there, or choose another --out")
    if not any((out / name).is_file() or any(out.glob(f".{name}.*.tmp")) for name in MARKS):
        return (f"--out {out}: --force replaces an earlier dsm grad's files (a folder with its "
                f"{' or '.join(MARKS)}); this one holds neither: choose another --out")
    for name in WRITTEN:
        (out / name).unlink(missing_ok=True)
        for tmp in out.glob(f".{name}.*.tmp"):      # report.io.atomic's, left by a run killed mid-write
            tmp.unlink(missing_ok=True)
    return unwritable(out)


def row_values(r) -> list:
    """A CheckRow as selfcheck.csv's values (None stays empty: undefined)."""
    return [r.technique, r.param, r.unit, r.loss, r.ad, r.fd, r.step, r.changed_texels, r.changed_pixels,
            r.changed_pairs, r.ad_vs_fd, r.closed_form, r.ad_vs_closed, r.edge_pairs]


def write_csv(rows, path: Path):
    """selfcheck.csv: exact values (repr), empty where undefined."""
    with atomic(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row_values(r)])


def _g(x, digits: int = 4) -> str:
    return "undefined" if x is None else f"{x:.{digits}g}"


def _pct(x) -> str:
    return "undefined" if x is None else f"{100.0 * x:.2f} %"


def table_text(spec, rows) -> str:
    """table.md: the self-check table per technique and parameter."""
    unit = loss_unit(spec)
    lines = [f"# Gradient self-check: {spec.scene}, {spec.light} light, loss {spec.loss} ({unit})", "",
             f"Map {spec.map_resolution}^2, image {spec.image_resolution}^2 over [-{spec.window:g}, "
             f"{spec.window:g}]^2, bias {spec.bias:g} world. AD: Dr.Jit reverse mode; FD: central difference "
             "(step halved until no texel, pixel or antialiasing pair changes; `changed` counts what still did: "
             "its AD vs FD is undefined); closed "
             "form: dsm.grad.check. Derivatives in the loss's unit per the parameter's unit.", "",
             "| technique | param | loss | AD | FD | AD vs FD | closed form | AD vs closed | step | changed (texels, pixels, pairs) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.technique} | {r.param} ({r.unit}) | {_g(r.loss)} | {_g(r.ad)} | {_g(r.fd)} | "
                     f"{_pct(r.ad_vs_fd)} | {_g(r.closed_form)} | {_pct(r.ad_vs_closed)} | {r.step:g} | "
                     f"{r.changed_texels}, {r.changed_pixels}, {r.changed_pairs} |")
    return "\n".join(lines) + "\n"


def main(args) -> int:
    """Run ``dsm grad``: read the config, check every technique, write the table."""
    try:
        spec = specmod.load(args.config)
    except ConfigError as e:
        print(f"dsm: config error: {e}", file=sys.stderr)
        return 2
    try:
        env.use_variant(args.variant)
    except env.SetupError as e:
        print(f"dsm: setup error: {e}", file=sys.stderr)
        return 3
    if getattr(args, "compare", False) and spec.loss not in comparemod.LOSSES:
        print(f"dsm: config error: {spec.source}: gradient.loss: --compare takes {spec.loss!r} loss only from a "
              f"reference of its own (valid: {', '.join(comparemod.LOSSES)})", file=sys.stderr)
        return 2
    blind = getattr(args, "compare", False) and unseen_problem(spec)
    if blind:
        print(f"dsm: config error: {blind}", file=sys.stderr)
        return 2
    out = Path(args.out)
    held, why = claim(out)
    if why is None:
        with held:
            why = folder_problem(out, getattr(args, "force", False))
            if why is None:
                return _run_held(args, spec, out)
    print(f"dsm: {why}", file=sys.stderr)
    return 2


def unseen_problem(spec) -> str | None:
    """Why --compare's projective integrators would see no ground pixel (None if they see some): the occluder's
    and an area light's images, grown by MASK_PIXELS, cover the whole image of their camera."""
    for p in spec.params:
        if p in projective.OCCLUDER_PARAMS and not projective.ground_seen(spec, p).any():
            key, what = (("light[0].size", "the occluder's and the area light's images cover")
                         if spec.light == "area" else ("scene[0].size", "the occluder's image covers"))
            return (f"{spec.source}: {key}: --compare's projective integrators would see no ground pixel: {what} "
                    f"the whole of [-{spec.window:g}, {spec.window:g}]^2 (grown by {projective.MASK_PIXELS} pixels); "
                    "make it smaller or the window larger")
    return None


def _run_held(args, spec, out: Path) -> int:
    """The run of ``dsm grad`` in its claimed folder ``out``: the measuring, then the report (report.html,
    its figures), each one's seconds in grad.json."""
    t0 = time.perf_counter()
    try:
        problem = Problem(spec)
    except ConfigError as e:
        print(f"dsm: config error: {e}", file=sys.stderr)
        return 2
    report_parts = {}
    rows = self_check(problem, progress=lambda r: print(f"  {r.technique}, {r.param}: AD {_g(r.ad)}, FD {_g(r.fd)}",
                                                        file=sys.stderr))
    write_csv(rows, out / "selfcheck.csv")
    text = table_text(spec, rows)
    write_text(out / "table.md", text)
    print(text)
    print(f"dsm grad: {len(rows)} rows in {out / 'selfcheck.csv'} and {out / 'table.md'}")
    timing = {"selfcheck_s": time.perf_counter() - t0}
    if getattr(args, "compare", False):
        t = time.perf_counter()
        report_parts.update(run_compare(problem, out))
        timing["compare_s"] = time.perf_counter() - t - report_parts["gradients.png"]
    if getattr(args, "inverse", False):
        t = time.perf_counter()
        run_inverse(problem, out)
        timing["inverse_s"] = time.perf_counter() - t
    timing["measure_s"] = sum(timing.values())
    write_report(args, spec, out, timing, report_parts)
    return 0


def run_record(args, spec, timing: dict) -> dict:
    """grad.json's record (the report's time added once it is written): config, options, variant,
    versions, the gradient's settings and the measuring's seconds."""
    import mitsuba as mi
    options = [f"--{o}" for o in ("compare", "inverse") if getattr(args, o, False)]
    return {"command": "dsm grad", "config_file": str(spec.source), "options": options, "variant": mi.variant(),
            "versions": env.versions(), "gradient": gradient_record(spec), "timing": dict(timing)}


def gradient_record(spec) -> dict:
    """The spec's settings as JSON values (techniques by their labels), with the loss's unit."""
    rec = {}
    for f in dataclasses.fields(spec):
        v = getattr(spec, f.name)
        rec[f.name] = [t.label for t in v] if f.name == "techniques" else list(v) if isinstance(v, tuple) else v
    rec["loss_unit"] = loss_unit(spec)
    return rec


def write_report(args, spec, out: Path, timing: dict, parts: dict):
    """report.html (dsm.grad.page) after the measuring, then grad.json with both times."""
    t = time.perf_counter()
    run = run_record(args, spec, timing)
    parts.update(page.write_report(out, run))
    run["timing"]["report_s"] = time.perf_counter() - t + parts.get("gradients.png", 0.0)
    run["timing"]["report_parts"] = parts
    write_json(out / "grad.json", run, indent=1)
    print(f"dsm grad: {out / page.PAGE} (measuring {timing['measure_s']:.1f} s, report "
          f"{run['timing']['report_s']:.1f} s)")


def run_compare(problem, out: Path) -> dict:
    """--compare: references, each technique against them, the projective integrators, the figure
    (returns the figure's seconds: the report's time, not the measuring's)."""
    spec = problem.spec
    refs = comparemod.references(problem)
    rows = comparemod.compare(problem, refs, progress=lambda r: print(
        f"  {r.technique}, {r.param}: AD {_g(r.ad)} vs {_g(r.reference)}", file=sys.stderr))
    tables.write_rows(out / "compare.csv", tables.COMPARE_COLUMNS, [tables.compare_values(r) for r in rows])
    proj, measured = [], {}
    for p in spec.params:
        if p not in projective.OCCLUDER_PARAMS:
            continue
        for name in spec.projective_integrators:
            res = projective.gradient(problem, name, p, spec.projective_spp, spec.projective_seeds)
            measured[name, p] = res
            seen_ref = refs[p].masked(res.seen)        # the truth over the pixels the integrator measures
            proj.append((res, seen_ref, comparemod.cosine(res.image, seen_ref.image)))
    tables.write_rows(out / "projective.csv", tables.PROJECTIVE_COLUMNS,
                      [tables.projective_values(*t) for t in proj])
    text = tables.compare_text(spec, refs, rows, proj)
    if spec.light == "area":
        text += run_equal_error(problem, refs, rows, out, measured)
    write_text(out / "compare.md", text)
    t = time.perf_counter()
    figure.draw(out / "gradients.png", _panels(refs, rows, proj), spec.window)
    drawn = time.perf_counter() - t
    print(text)
    return {"gradients.png": drawn}


def run_equal_error(problem, refs, rows, out: Path, measured: dict | None = None) -> str:
    """--compare under an area light: path tracing's error curve per integrator and occluder parameter,
    each technique's spp and time at equal error; equal_error.csv, equal_error_curve.csv, equal_error.png
    and the section of compare.md it returns (``measured``: the projective runs by (integrator, parameter),
    reused at their count of the sweep)."""
    spec = problem.spec
    curves, eq = [], []
    for p in spec.params:
        if p not in projective.OCCLUDER_PARAMS:
            continue
        seen = projective.visible_ground(problem, p)
        for name in spec.projective_integrators:
            points = equal_error.curve(problem, name, p, refs[p], (measured or {}).get((name, p)))
            for q in points:
                print(f"  {name}, {p}, {q.spp} spp: rel. RMS error {_g(q.rel_rms_error)}, {q.ms:.0f} ms", file=sys.stderr)
            curves.append(points)
            eq += equal_error.rows(problem, rows, points, seen)
    tables.write_rows(out / "equal_error_curve.csv", tables.CURVE_COLUMNS,
                      [tables.curve_values(q) for c in curves for q in c])
    tables.write_rows(out / "equal_error.csv", tables.EQUAL_ERROR_COLUMNS, [tables.equal_error_values(r) for r in eq])
    figure.draw_equal_error(out / "equal_error.png", curves, eq)
    return tables.equal_error_text(curves, eq)


def _panels(refs, rows, proj) -> dict:
    panels = {}
    for p, r in refs.items():
        row = [("reference (exact FD)", r.image)]
        row += [(c.technique, c.image) for c in rows if c.param == p]
        row += [(res.integrator, res.image) for res, _, _ in proj if res.param == p]
        panels[p] = row
    return panels


def run_inverse(problem, out: Path):
    """--inverse: the inverse task's runs, inverse.csv and inverse.md."""
    runs = inverse.run_inverse(problem, progress=lambda r: print(
        f"  {r.technique}, {r.param}, start {r.start_offset:+g}: error {r.final_error:.3g}", file=sys.stderr))
    tables.write_rows(out / "inverse.csv", tables.INVERSE_COLUMNS, [tables.inverse_values(r) for r in runs])
    text = tables.inverse_text(problem.spec, runs)
    write_text(out / "inverse.md", text)
    print(text)
