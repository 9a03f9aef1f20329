"""A derivation (:mod:`dsm.config.derive`) as files and lines: ``derived.toml`` (a config a user can
edit and run, each choice's reason a comment), ``derivation.json`` (the record the report reads)
and the lines ``dsm plan SCENE.xml [--explain]`` and ``dsm run SCENE.xml`` print."""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

from .read import parse

DERIVED_TOML = "derived.toml"
DERIVATION_JSON = "derivation.json"


def toml_value(v) -> str:
    """One TOML value: strings quoted (JSON escapes are TOML's), numbers exact, lists inline."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, int):
        return str(v)
    return json.dumps(str(v))


def toml_text(d) -> str:
    """derived.toml: the reasons as a comment block, then the tables (offered lines commented out)."""
    lines = [f"# Derived by dsm from {d.measured['scene']} (dsm run on the scene file): one line a choice.",
             "# Edit and run it again: dsm run derived.toml", "#"]
    lines += [f"# {c.rule}: {c.choice}. Why: {c.reason}." for c in d.choices]
    for name, value in d.tables.items():
        rows = value if isinstance(value, list) else [value]
        for row in rows:
            lines += ["", f"[[{name}]]" if isinstance(value, list) else f"[{name}]"]
            lines += [f"{k} = {toml_value(v)}" for k, v in row.items()]
            lines += [f"# {line}    # {why}" for table, line, why in d.offered if table == name]
    return "\n".join(lines) + "\n"


def record(d) -> dict:
    """derivation.json: the choices (rule, choice, reason), the offered lines and the measured quantities."""
    return {"choices": [{"rule": c.rule, "choice": c.choice, "reason": c.reason} for c in d.choices],
            "offered": [{"table": t, "line": line, "reason": why} for t, line, why in d.offered],
            "measured": d.measured}


def reason_lines(d) -> list:
    """One line per choice: what was derived and why (the console's and the plan's)."""
    return [f"derived {c.rule}: {c.choice} ({c.reason})" for c in d.choices]


def explain_lines(d) -> list:
    """The measured quantities behind the rules, one line each (``dsm plan SCENE.xml --explain``)."""
    m = d.measured
    g = lambda x: "undefined" if x is None else f"{x:.4g}"
    out = [f"scene {m['scene']}: film {m['film'][0]} x {m['film'][1]}, footprints measured at "
           f"{m['measure_resolution']} texels a side"]
    for v in m["views"]:
        out.append(f"  {v['light']} {v['view']}: {v['receivers']} receivers, footprint (texels per pixel) median "
                   f"{g(v['footprint_median'])}, min {g(v['footprint_min'])}, max {g(v['footprint_max'])}, ratio "
                   f"{g(v['footprint_ratio'])}; depth range {g(v['depth_near'])} to {g(v['depth_far'])}")
    for light in m["lights"]:
        out.append(f"  {light['light']}: median footprint {g(light['footprint_median'])}: one texel per pixel at "
                   f"{g(light['resolution_exact'])} (so {light['resolution']})")
    out.append(f"  the finest median texel there {g(m['texel_world_finest'])} world units")
    out.append(f"  closed meshes: {', '.join(m['closed_meshes']) or 'none'}; open: {', '.join(m['open_meshes']) or 'none'}")
    out.append(f"  largest |coordinate| {m['max_abs_coordinate']:.6g} (float32 step {m['f32_step']:.3g}); "
               f"diagonal {m['diagonal']:.4g}")
    return out


def config_of(d, out=None, source: str | None = None):
    """The Config of derivation ``d`` as derived.toml in folder ``out`` reads (its source that file)."""
    where = Path(out) / DERIVED_TOML if out is not None else None
    return parse(tomllib.loads(toml_text(d)), source or str(where), where.parent if where else None)


def write(d, out):
    """derived.toml and derivation.json into the results folder ``out``."""
    out = Path(out)
    (out / DERIVED_TOML).write_text(toml_text(d), encoding="utf-8")
    (out / DERIVATION_JSON).write_text(json.dumps(record(d), indent=1) + "\n", encoding="utf-8")
