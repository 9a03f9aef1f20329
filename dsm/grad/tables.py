"""``dsm grad --compare`` and ``--inverse`` outputs: CSV files (exact values) and Markdown tables.

Every CSV number is Python's repr (exact to paste back); an undefined value is an empty cell, and
in the Markdown tables the word ``undefined``. A projective integrator's gradient is marked
``agrees`` where its mean is within three combined errors (its standard error over seeds, the
reference's own error) of the supersampled reference, else ``disagrees``: a finding.
"""
from __future__ import annotations

import csv
from pathlib import Path

from ..report.io import atomic
from .check import relative_within
from .inverse import success_rate

COMPARE_COLUMNS = ("technique", "param", "unit", "ad", "reference", "reference_error", "reference_step",
                   "reference_samples", "rel_error", "sign", "cosine", "ms_per_gradient", "compile_ms")
PROJECTIVE_COLUMNS = ("integrator", "param", "spp", "seeds", "mean", "standard_error", "bias", "rel_error",
                      "reference", "reference_error", "agrees", "primal_mismatch", "cosine", "ms_per_gradient")
INVERSE_COLUMNS = ("technique", "param", "unit", "start_offset", "final_error", "success", "converged_at",
                   "seconds_to_converge", "seconds")
AGREE_SIGMAS = 3.0
CURVE_COLUMNS = ("integrator", "param", "spp", "seeds", "mean", "bias", "standard_error", "rel_rms_error", "truth",
                 "truth_error", "ms_per_gradient", "first_ms")
EQUAL_ERROR_COLUMNS = ("technique", "param", "integrator", "ad", "truth", "rel_error", "ms_per_gradient",
                       "pt_spp", "pt_ms_per_gradient", "time_ratio", "status")


def _cell(v):
    return "" if v is None else repr(v) if isinstance(v, float) else v


def write_rows(path: Path, columns, rows):
    """A CSV of ``rows`` (lists of values in ``columns``' order)."""
    with atomic(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([_cell(v) for v in r])


def compare_values(r) -> list:
    """A CompareRow as compare.csv's values."""
    return [r.technique, r.param, r.unit, r.ad, r.reference, r.reference_error, r.reference_step,
            r.reference_samples, r.rel_error, r.sign, r.cosine, r.ms, r.compile_ms]


def agrees(result, ref) -> bool | None:
    """Whether a projective gradient's mean is within AGREE_SIGMAS combined errors of the reference; None
    where the truth over its pixels is 0 +- 0 (the mask hid the shadow: 0 against 0 is no agreement)."""
    if ref.value == 0.0 and ref.error == 0.0:
        return None
    return abs(result.mean - ref.value) <= AGREE_SIGMAS * (result.spread + ref.error)


def verdict(result, ref) -> str:
    """compare.md's word for a projective gradient: agrees, disagrees or measured nothing."""
    return {True: "agrees", False: "disagrees", None: "measured nothing"}[agrees(result, ref)]


def projective_values(p, ref, cos) -> list:
    """A ProjectiveResult (against its Reference) as projective.csv's values."""
    return [p.integrator, p.param, p.spp, len(p.grads), p.mean, p.spread, p.mean - ref.value,
            relative_within(p.mean, ref.value, ref.error), ref.value, ref.error, agrees(p, ref), p.primal_mismatch, cos,
            p.ms]


def curve_values(q) -> list:
    """An equal_error.SppPoint as equal_error_curve.csv's values."""
    return [q.integrator, q.param, q.spp, len(q.grads), q.mean, q.bias, q.standard_error, q.rel_rms_error, q.truth,
            q.truth_error, q.ms, q.first_ms]


def equal_error_values(r) -> list:
    """An equal_error.EqualErrorRow as equal_error.csv's values."""
    return [r.technique, r.param, r.integrator, r.ad, r.truth, r.error, r.ms, r.spp, r.pt_ms, r.time_ratio, r.status]


def equal_error_text(curves, rows) -> str:
    """compare.md's section on cost at equal gradient error: each curve, then each technique's match."""
    out = ["", "## Cost at equal gradient error", "",
           "Over the pixels the camera sees of the ground (the truth masked alike). Path tracing's relative RMS "
           "error over seeds against the truth, its bias and standard error, ms per gradient (warm median; the "
           "first seed, with its compile, apart):", "",
           "| integrator | param | spp x seeds | rel. RMS error | bias | std. error | ms per gradient |",
           "|---|---|---|---|---|---|---|"]
    for c in curves:
        for q in c:
            out.append(f"| {q.integrator} | {q.param} | {q.spp} x {len(q.grads)} | {_pct(q.rel_rms_error)} | "
                       f"{_g(q.bias, 3)} | {_g(q.standard_error, 2)} | {q.ms:.0f} |")
        out.append(f"| {c[0].integrator} | {c[0].param} | truth | {_g(c[0].truth)} +- {_g(c[0].truth_error, 2)} | | | |")
    out += ["", "Each technique: its relative error and ms, the spp at which path tracing's error first reaches it "
            "(log-log interpolation), path tracing's ms there, and their ratio:", "",
            "| technique | param | integrator | rel. error | ms | path tracing spp | its ms | time ratio | status |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r.technique} | {r.param} | {r.integrator} | {_pct(r.error)} | {r.ms:.1f} | {_g(r.spp, 3)} | "
                   f"{_g(r.pt_ms, 4)} | {_g(r.time_ratio, 3)} | {r.status} |")
    return "\n".join(out) + "\n"


def inverse_values(r) -> list:
    """An InverseRun as inverse.csv's values."""
    return [r.technique, r.param, r.unit, r.start_offset, r.final_error, r.success, r.converged_at,
            r.seconds_to_converge, r.seconds]


def _g(x, digits: int = 4) -> str:
    return "undefined" if x is None else f"{x:.{digits}g}"


def _pct(x) -> str:
    return "undefined" if x is None else f"{100.0 * x:.1f} %"


def compare_text(spec, refs, rows, projective) -> str:
    """compare.md: the references, each technique against them, the projective integrators."""
    out = [f"# Gradients against the truth: {spec.scene}, {spec.light} light, loss {spec.loss}", "",
           "Reference: central difference of the exact image, supersampled (stratified receivers per pixel); "
           "its error is the larger change under halving the step or another seed of the receivers.", "",
           "| param | reference | its error | step | receivers per pixel |", "|---|---|---|---|---|"]
    for p, r in refs.items():
        out.append(f"| {p} ({spec.unit(p)}) | {_g(r.value)} | {_g(r.error, 2)} | {r.step:g} | {r.samples} |")
    out += ["", "| technique | param | AD | rel. error | sign | cosine (per-pixel) | ms per gradient | compile ms |",
            "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        sign = "undefined" if r.sign is None else r.sign
        out.append(f"| {r.technique} | {r.param} | {_g(r.ad)} | {_pct(r.rel_error)} | {sign} | {_g(r.cosine, 3)} | "
                   f"{r.ms:.1f} | {r.compile_ms:.0f} |")
    if projective:
        out += ["", "Mitsuba's projective integrators (mean over seeds, its standard error; `agrees`: within "
                f"{AGREE_SIGMAS:g} combined errors of the reference, else a finding):", "",
                "| integrator | param | spp x seeds | mean | std. error | rel. error | verdict | ms per gradient |",
                "|---|---|---|---|---|---|---|---|"]
        for p, ref, _ in projective:
            out.append(f"| {p.integrator} | {p.param} | {p.spp} x {len(p.grads)} | {_g(p.mean)} | {_g(p.spread, 2)} | "
                       f"{_pct(relative_within(p.mean, ref.value, ref.error))} | {verdict(p, ref)} | "
                       f"{p.ms:.1f} |")
    return "\n".join(out) + "\n"


def inverse_text(spec, runs) -> str:
    """inverse.md: per technique and parameter, the success rate, iterations, time, final error."""
    out = [f"# Inverse task: {spec.scene}, {spec.light} light", "",
           f"Adam on one parameter from the truth + each start offset {list(spec.inverse_starts)}, "
           f"{spec.inverse_iterations} iterations, l2 loss against the exact image; success: final error "
           f"within {spec.inverse_tolerance:g}.", "",
           "| technique | param | success | median iterations to converge | median s to converge | median final error |",
           "|---|---|---|---|---|---|"]
    groups = {}
    for r in runs:
        groups.setdefault((r.technique, r.param), []).append(r)
    for (tech, param), rs in groups.items():
        ok = [r for r in rs if r.converged_at is not None]
        its = _median([r.converged_at for r in ok])
        secs = _median([r.seconds_to_converge for r in ok])
        out.append(f"| {tech} | {param} | {sum(r.success for r in rs)}/{len(rs)} ({_pct(success_rate(rs))}) | "
                   f"{_g(its)} | {_g(secs, 3)} | {_g(_median([r.final_error for r in rs]), 3)} |")
    return "\n".join(out) + "\n"


def _median(xs):
    if not xs:
        return None
    s = sorted(xs)
    n = len(s)
    return float(s[n // 2]) if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2.0
