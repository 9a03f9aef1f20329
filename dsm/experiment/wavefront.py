"""A map's lookup wavefront: every depth case of one map (scheme instance x filter x stored
format) traced first and evaluated together, so that their lookups run as one launch per array
size (`[timing] lookups = "wavefront"`, the default) instead of one per case and repeat.

**What a case's time is.** A shared launch's time cannot be split among its cases without
assuming the answer (which case costs what), so it is not split: the wavefront's own kernel time
is the map's ``lookup_wave_ms`` (run.json's map record), and a case's ``lookup_ms`` is the
kernel time of its own lookup timed alone on the same receivers, ``[timing] repeats`` calls,
**once per kernel**: cases that differ only in numeric parameter values (opaque Dr.Jit
scalars) run the same compiled kernel over the same receivers and share that measurement
(``lookup_shared``: how many of the map's cases run that kernel). A case's visibility, attached-shadow
lookup and plane fallbacks come from the wavefront (the last of its timed calls), the same bits
as its own lookup gives (tests/test_wavefront.py). ``lookups = "per_case"`` times every case's
own lookup instead (the kit's earlier behaviour).

A wavefront's outputs are held at once: a map's cases are cut into waves of at most
:func:`dsm.config.plan.wave_cases` cases, so one wave's outputs fit ``WAVE_BYTES``.
"""
from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass

import drjit as dr
import numpy as np

from .. import pipeline
from ..core import timing
from ..core.types import Length
from ..config import plan as planmod


@dataclass
class Looked:
    """One case's lookups from its map's wavefront (numpy) and the Timing that stands for its lookup."""
    v: np.ndarray            # V per receiver
    v_back: np.ndarray       # V of the attached-shadow (back-facing) receivers
    misses: int              # receivers whose texel ray misses their tangent plane (0 without a plane)
    timing: timing.Timing    # its kernel timed alone (shared by the cases of the same kernel)
    shared: int              # how many cases of the map that timing stands for


def kernel_key(spec, filt: str, fmt: str) -> tuple:
    """What a case's lookup kernel depends on: its scheme, each parameter's kind (a length's unit;
    a non-number by value), its filter and stored format. Numbers are opaque, so not their values."""
    kinds = []
    for f in dataclasses.fields(spec.params):
        val = getattr(spec.params, f.name)
        if isinstance(val, Length):
            kinds.append((f.name, "length", val.unit))
        elif isinstance(val, (int, float)) and not isinstance(val, bool):
            kinds.append((f.name, "number"))
        else:
            kinds.append((f.name, repr(val)))
    return spec.name, tuple(kinds), filt, fmt


def _attached(spec, filt, fmt, stored, rxs, backs, seed) -> tuple:
    """The lazy (V of the back-facing receivers, plane misses) of one case, each None where it has none."""
    back = backs[fmt]
    v_back = None if back is None else pipeline.visibility(spec, back, stored[fmt], filt, seed)[0]
    return v_back, None if rxs[fmt] is None else pipeline.plane_misses(spec, rxs[fmt], stored[fmt])


def _numpy(v_back, miss) -> tuple:
    """(V of the back-facing receivers, how many plane misses) of evaluated :func:`_attached` outputs."""
    return np.zeros(0) if v_back is None else v_back.numpy(), 0 if miss is None else int(np.count_nonzero(miss.numpy()))


def _trace(spec, filt, fmt, stored, rxs, backs, seed) -> tuple:
    """The lazy (V, tap shape, V of the back-facing receivers or None, plane misses or None) of one case."""
    v, tap = pipeline.visibility(spec, rxs[fmt], stored[fmt], filt, seed)
    return v, tap, *_attached(spec, filt, fmt, stored, rxs, backs, seed)


def attached_only(cases, stored, rxs, backs, seed) -> dict:
    """``lookups = "per_case"``: {(spec, filter, format): (V of the back-facing receivers, plane
    misses)} of ``cases``, evaluated together (one launch per array size, not two per case), each
    case timing its own lookup in the runner; a case whose expressions fail here is left out (its own
    lookups then run, and fail, in its case), and all are where the evaluation fails."""
    lazy = {}
    for c in cases:
        try:
            lazy[c] = _attached(*c, stored, rxs, backs, seed)
        except Exception:
            continue
    try:
        dr.eval(*[x for pair in lazy.values() for x in pair if x is not None])
    except Exception:
        return {}
    return {c: _numpy(*pair) for c, pair in lazy.items()}


def _evaluated(cases, stored, rxs, backs, seed, repeats) -> tuple:
    """({case: its three kept outputs, numpy}, the wave's Timing) of one wave, or ({}, None) where it fails
    (its cases then look up on their own, and fail there with their own message)."""
    traced = {}

    def wave():
        """Every case's outputs traced (a case whose tracing fails is left out), flattened for the clock."""
        traced.clear()
        for c in cases:
            try:
                traced[c] = _trace(*c, stored, rxs, backs, seed)
            except Exception:
                continue
        return tuple(x for outs in traced.values() for x in outs if x is not None)
    try:
        _, t = timing.measure_kernel(wave, repeats)
    except Exception:
        return {}, None
    # the tap shapes are traced and timed as the case's own lookup returns them, not kept: the acne
    # split reads dsm.case.evaluation's own-surface test
    out = {c: (v.numpy(), *_numpy(vb, miss)) for c, (v, _, vb, miss) in traced.items()}
    return out, t


def run(cases: list, stored: dict, rxs: dict, backs: dict, seed: int, repeats: int, family=None) -> tuple:
    """({(spec, filter, format): Looked}, the map's record {lookup_wave_ms, waves, wave_cases}) of
    the depth cases ``cases`` of one map (``stored``, ``rxs``, ``backs``: per stored format); a case
    left out (no receivers, or its wave failed) looks up on its own in the runner. ``family``: all
    the map's depth cases (default ``cases``; with a resumed run's kept ones), over which a case's
    ``shared`` counts the cases of its kernel, so that it does not depend on what was resumed."""
    family = cases if family is None else family
    cases = [c for c in cases if rxs[c[2]] is not None]
    n_rx = max((dr.width(rxs[f].u_map) for f in {c[2] for c in cases}), default=0)
    n_back = max((dr.width(backs[f].u_map) for f in {c[2] for c in cases} if backs[f] is not None), default=0)
    per_wave = planmod.wave_cases(n_rx, n_back)
    looked, wave_ms, waves = {}, 0.0, 0
    solo = {}                                  # kernel key -> Timing of its first case, timed alone
    for first in range(0, len(cases), per_wave):
        out, t = _evaluated(cases[first:first + per_wave], stored, rxs, backs, seed, repeats)
        if t is not None:
            wave_ms, waves = wave_ms + t.ms, waves + 1
        for c, (v, v_back, misses) in out.items():
            key = kernel_key(*c)
            if key not in solo:
                spec, filt, fmt = c
                solo[key] = timing.measure_kernel(
                    lambda: pipeline.visibility(spec, rxs[fmt], stored[fmt], filt, seed), repeats)[1]
            looked[c] = Looked(v, v_back, misses, solo[key], 0)
    shared = Counter(kernel_key(*c) for c in family)
    for c, lk in looked.items():
        lk.shared = shared[kernel_key(*c)]
    return looked, {"lookup_wave_ms": wave_ms if waves else None, "waves": waves, "wave_cases": len(looked)}
