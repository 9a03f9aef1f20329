"""``dsm grad CONFIG``: the self-check table of a config's ``[gradient]`` table.

Writes ``selfcheck.csv`` (one row per technique and parameter, every number as Python's repr:
exact to paste back) and ``table.md`` (the same, rounded for reading) into ``--out``, and prints
the table. A relative error whose reference is 0 is undefined and shown as such, never as 0.
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

from ..core import env
from ..core.types import VARIANTS, ConfigError
from . import spec as specmod
from .check import loss_unit, self_check
from .problem import Problem

COLUMNS = ("technique", "param", "unit", "loss", "ad", "fd", "fd_step", "changed_texels", "changed_pixels",
           "ad_vs_fd", "closed_form", "ad_vs_closed", "edge_pairs")


def add_parser(sub):
    """Add the ``grad`` subcommand to an argparse subparsers object."""
    g = sub.add_parser("grad", help="gradients of the shadowed image in scene parameters, per technique: AD "
                       "against central differences and closed forms (a config's [gradient])")
    g.add_argument("config", help="TOML file with a [gradient] table")
    g.add_argument("--out", default="grad", help="folder for selfcheck.csv and table.md (default: grad/)")
    g.add_argument("--variant", choices=VARIANTS, help="Mitsuba variant (default llvm_ad_rgb)")
    return g


def row_values(r) -> list:
    """A CheckRow as selfcheck.csv's values (None stays empty: undefined)."""
    return [r.technique, r.param, r.unit, r.loss, r.ad, r.fd, r.step, r.changed_texels, r.changed_pixels,
            r.ad_vs_fd, r.closed_form, r.ad_vs_closed, r.edge_pairs]


def write_csv(rows, path: Path):
    """selfcheck.csv: exact values (repr), empty where undefined."""
    with open(path, "w", newline="") as fh:
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
             "(step halved until no texel or pixel changes class; `changed` counts what still did); closed "
             "form: dsm.grad.check. Derivatives in the loss's unit per the parameter's unit.", "",
             "| technique | param | loss | AD | FD | AD vs FD | closed form | AD vs closed | step | changed (texels, pixels) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.technique} | {r.param} ({r.unit}) | {_g(r.loss)} | {_g(r.ad)} | {_g(r.fd)} | "
                     f"{_pct(r.ad_vs_fd)} | {_g(r.closed_form)} | {_pct(r.ad_vs_closed)} | {r.step:g} | "
                     f"{r.changed_texels}, {r.changed_pixels} |")
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
        print(f"dsm: {e}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    problem = Problem(spec)
    rows = self_check(problem, progress=lambda r: print(f"  {r.technique}, {r.param}: AD {_g(r.ad)}, FD {_g(r.fd)}",
                                                        file=sys.stderr))
    write_csv(rows, out / "selfcheck.csv")
    text = table_text(spec, rows)
    (out / "table.md").write_text(text)
    print(text)
    print(f"dsm grad: {len(rows)} rows in {out / 'selfcheck.csv'} and {out / 'table.md'}")
    return 0
