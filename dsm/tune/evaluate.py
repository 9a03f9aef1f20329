"""The exact (hard) objective's counts of a scheme instance with the kit's nearest lookup."""
from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import time

import drjit as dr

from .. import pipeline as pl
from ..core.types import Length, SchemeSpec


NAN = float("nan")       # one object: lists of rows compare equal where both hold it


# ---------------------------------------------------------------- what a search ran, counted

@dataclasses.dataclass
class Tally:
    """The evaluations a search made, counted where they run: ``exact``, the exact objective's counts at one
    parameter point over a set of receivers (hard_counts); ``relaxed``, a pass of the relaxed loss (forward, and
    backward where AD follows: relax.relaxed_loss); ``line``, an exact line search (the margins linearised along
    a line and the objective counted at every receiver's flip: refine.margin_line)."""
    exact: int = 0
    relaxed: int = 0
    line: int = 0

    def as_dict(self) -> dict:
        """The counts by kind, for tune.json."""
        return dataclasses.asdict(self)


_ACTIVE = contextvars.ContextVar("dsm_tune_tally", default=None)


@contextlib.contextmanager
def tallying():
    """Count the evaluations made inside the block into a new Tally (nested blocks count into their own only)."""
    tally = Tally()
    token = _ACTIVE.set(tally)
    try:
        yield tally
    finally:
        _ACTIVE.reset(token)


def count(kind: str):
    """One evaluation of ``kind`` (exact, relaxed, line) made: counted into the active Tally, if any."""
    tally = _ACTIVE.get()
    if tally is not None:
        setattr(tally, kind, getattr(tally, kind) + 1)


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
    count("exact")
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
