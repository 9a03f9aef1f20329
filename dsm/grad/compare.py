"""Each technique's gradient against the primary truth (:mod:`.reference`), and its cost.

Per technique and parameter: the AD derivative of the loss against the supersampled central
difference of the exact image (relative error, and whether the sign agrees), the cosine
similarity of the per-pixel gradient images (the technique's forward-mode tangent per receiver
against the reference's per-pixel difference), and the cost of one gradient: a full evaluation
(map, edge weights, lookup, loss and its forward-mode derivative) in ms, the median of warm
calls with ``dr.sync_thread()`` around each clock read and the first call's compile reported
apart (:func:`dsm.core.timing.measure`). A ratio with an empty denominator is None (undefined).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import timing
from .check import relative_within
from .evaluation import case_of, evaluate
from .reference import reference

REPEATS = 3
LOSSES = ("shadow_area", "shadow_moment_x")     # the losses the supersampled reference computes


@dataclass
class CompareRow:
    """One technique and parameter against the reference."""
    technique: str
    param: str
    unit: str
    ad: float
    reference: float
    reference_error: float
    reference_step: float
    reference_samples: int
    cosine: float | None          # of the per-pixel gradient images; None where either is all zero
    ms: float                     # one gradient, warm median
    compile_ms: float
    image: np.ndarray = None      # the technique's per-pixel tangent (N, N)

    @property
    def rel_error(self) -> float | None:
        """|AD - reference| / |reference| (None where the reference is within its own error of 0)."""
        return relative_within(self.ad, self.reference, self.reference_error)

    @property
    def sign(self) -> str | None:
        """AD's sign against the reference's: ``agrees``, ``opposite`` or ``zero`` (AD is 0); None (undefined)
        where the reference is within its own error of 0."""
        if abs(self.reference) <= self.reference_error:
            return None
        if self.ad == 0.0:
            return "zero"
        return "agrees" if np.sign(self.ad) == np.sign(self.reference) else "opposite"


def cosine(a: np.ndarray, b: np.ndarray) -> float | None:
    """Cosine similarity of two images (float64), None where either is all zero."""
    a, b = np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0.0 or nb == 0.0:
        return None
    return float(np.dot(a, b) / (na * nb))


def tangent_image(problem, tech, param: str) -> np.ndarray:
    """The technique's dV / d ``param`` per pixel (N, N) by forward-mode AD (zeros where V ignores it)."""
    V, vals = problem.image_of(tech, problem.values(), (param,))[:2]
    dV = problem.tangent(V, vals[param])
    N = problem.spec.image_resolution
    return np.zeros((N, N)) if dV is None else dV.reshape(N, N).astype(np.float64)


def cost(problem, tech, param: str) -> timing.Timing:
    """One gradient's cost (ms): a full evaluation with its derivative, warm median, compile apart."""
    timing.enable_history()
    values = problem.values()
    return timing.measure(lambda: (problem.evaluate(tech, values, (param,)),), REPEATS)[1]


def references(problem) -> dict:
    """The supersampled reference of every parameter of the spec."""
    spec = problem.spec
    return {p: reference(problem, p, spec.reference_samples, spec.reference_step_of(p)) for p in spec.params}


def compare(problem, refs: dict, progress=None) -> list:
    """Every technique of the spec against the references ``refs`` (param -> Reference), per parameter."""
    spec = problem.spec
    rows = []
    for tech in spec.techniques:
        for p in spec.params:
            t = cost(problem, tech, p)
            ev = evaluate(problem, case_of(spec, tech), None, (p,))
            r, img = refs[p], tangent_image(problem, tech, p)
            rows.append(CompareRow(tech.label, p, spec.unit(p), ev.grads[p], r.value, r.error, r.step, r.samples,
                                   cosine(img, r.image), t.ms, t.compile_ms, img))
            if progress:
                progress(rows[-1])
    return rows
