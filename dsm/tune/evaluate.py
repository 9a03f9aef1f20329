"""The exact (hard) objective's counts of a scheme instance with the kit's nearest lookup."""
from __future__ import annotations

import dataclasses
import time

import drjit as dr

from .. import pipeline as pl
from ..core.types import Length, SchemeSpec


NAN = float("nan")       # one object: lists of rows compare equal where both hold it


# ---------------------------------------------------------------- hard (exact) evaluation

def with_values(spec: SchemeSpec, values: dict) -> SchemeSpec:
    """The scheme instance with tuned values (numbers, in each parameter's own unit)."""
    upd = {}
    for k, v in values.items():
        cur = getattr(spec.params, k)
        upd[k] = Length(float(v), cur.unit) if isinstance(cur, Length) else float(v)
    return SchemeSpec(spec.name, dataclasses.replace(spec.params, **upd))


def hard_counts(spec: SchemeSpec, cases, groups) -> dict:
    """Exact counts of one scheme instance over ``cases`` with the kit's nearest lookup."""
    culling = pl.culling_of(spec.params)
    return counted(cases, lambda c: pl.visibility(spec, c.rx, groups[c.group].maps[culling])[0])


def counted(cases, visibility) -> dict:
    """Exact counts over ``cases`` of the V ``visibility(case)`` gives (Dr.Jit; lit: V >= 0.5)."""
    acne = pp = n = lit = 0
    for c in cases:
        on = visibility(c).numpy() >= 0.5
        acne += int((c.v_star & ~on).sum())
        pp += int((~c.v_star & on).sum())
        n += c.n
        lit += int(c.v_star.sum())
    return counts(acne, pp, n, lit)


def counts(acne, pp, n, lit) -> dict:
    """Counts and rates of acne and peter-panning over n receivers, lit of them truly lit."""
    sh = n - lit
    nan = float("nan")
    return {"n_receivers": n, "n_gt_lit": lit, "n_gt_shadowed": sh, "n_acne": acne, "n_peterpan": pp,
            "acne_rate": acne / lit if lit else nan, "peterpan_rate": pp / sh if sh else nan,
            "error_rate": (acne + pp) / n if n else nan}


def sync_clock():
    """The time in seconds once Dr.Jit's queued work is done (a clock for timings)."""
    dr.sync_thread()
    return time.perf_counter()
