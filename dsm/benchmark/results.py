"""A benchmark run's results: the suite run through dsm.run, one JSON per run with its provenance."""
from __future__ import annotations

import json
import os
import platform
from pathlib import Path

from .suite import cases, load_suite, suite_sha256

MEASURES = ("n_receivers", "n_acne", "n_peterpan", "acne_rate", "peterpan_rate", "error_rate", "texel_size",
            "build_ms", "lookup_ms")
ORACLE_MEASURES = ("world_objective", "texel_objective", "per_texel_objective")


def machine() -> dict:
    """The machine a run measured on: CPU model, core count, OS."""
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "system": platform.platform()}


def light_kind(light_label: str) -> str:
    """``directional``, ``spot`` or ``point`` from a row's light label (``0:directional``)."""
    return light_label.split(":", 1)[-1]


def contender_of(row: dict) -> str:
    """The contender a metrics row belongs to: its preset's name, else its scheme's."""
    return row["preset"] or row["scheme"]


def case_records(case, results) -> list:
    """The suite's records of one (scene, unit) run: one per light and contender, plus its oracle floor."""
    out = []
    for row in results.rows:
        rec = {"scene": case.scene, "unit": case.unit, "light": light_kind(row["light"]),
               "contender": contender_of(row), "params": row["params"]}
        rec.update({k: row[k] for k in MEASURES})
        out.append(rec)
    for light in sorted({light_kind(o["light"]) for o in results.oracle}):
        rows = [o for o in results.oracle if light_kind(o["light"]) == light]
        best = min(rows, key=lambda o: o["per_texel_objective"])     # the floor over the cullings run
        rec = {"scene": case.scene, "unit": case.unit, "light": light, "contender": "oracle",
               "n_receivers": best["n_receivers"]}
        rec.update({k: float(min(o[k] for o in rows)) for k in ORACLE_MEASURES})
        out.append(rec)
    return out


def run_suite(size: str = "default", variant: str | None = None, progress=print) -> dict:
    """Run the suite at ``size`` and return its result document (see :func:`write`)."""
    import dsm
    from ..tools.env import versions
    suite = load_suite()
    todo = cases(suite, size)
    records, run_variant = [], None
    for i, case in enumerate(todo):
        if progress:
            progress(f"dsm benchmark: {i + 1}/{len(todo)} {case.scene} in {case.unit} (scale {case.scale:g})")
        res = dsm.run(case.config, variant=variant)
        run_variant = res.run.get("variant")
        records += case_records(case, res)
    return {"suite": suite["suite"]["name"], "suite_sha256": suite_sha256(), "size": size,
            "dsm_version": dsm.__version__, "versions": versions(), "variant": run_variant,
            "machine": machine(), "cases": records}


def write(doc: dict, out: Path) -> Path:
    """Write the result document as ``results.json`` in ``out``; returns its path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.json"
    path.write_text(json.dumps(doc, indent=1))
    return path


def read(path: Path) -> dict:
    """A result document from its JSON file."""
    return json.loads(Path(path).read_text())
