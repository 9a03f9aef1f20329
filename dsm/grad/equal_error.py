"""Cost at equal gradient error: path tracing's error against samples per pixel, and each technique's match.

Worchel & Alexa ("Differentiable Shadow Mapping for Efficient Inverse Graphics", CVPR 2023) claim
a shadow-map gradient is cheaper than a differentiable path tracer's of the same quality. Here it
is measured where the path tracer is right: under an area light, where Mitsuba's projective
integrators (:mod:`.projective`) agree with the truth. For each samples-per-pixel count of
``equal_error_spp`` the integrator's gradient over ``equal_error_seeds`` seeds gives its relative
RMS error against the truth (bias and spread together), its bias and standard error, and its ms
per gradient (warm median over the seeds, the first seed's compile apart). Every quantity is the
loss over the pixels the camera sees of the ground (:meth:`.reference.Reference.masked`), the
techniques' too, so both errors measure the same derivative.

For each technique, :func:`crossing` finds the spp at which the path tracer's error first reaches
the technique's (interpolated linearly on the log-log curve between the counts that bracket it);
the path tracer's ms there (interpolated the same way) over the technique's ms is the time ratio.
Where the curve starts at or below the technique's error, the first count and its ms are given as
upper bounds (status BELOW); where it never reaches it, there is no spp (NEVER).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import projective
from .check import relative

REACHED = "reached"                     # the curve crosses the technique's error within the sweep
BELOW = "already at the first spp"      # the fewest samples are as good already: spp and ms are upper bounds
NEVER = "never within the range"        # the most samples are still worse
UNDEFINED = "undefined"                 # the technique's error is undefined (a zero truth)
DISAGREES = "integrator disagrees with the truth"


@dataclass
class SppPoint:
    """Path tracing's gradient at one spp count over seeds, against the (masked) truth."""
    integrator: str
    param: str
    spp: int
    grads: tuple
    truth: float
    truth_error: float
    ms: float                    # warm median over the seeds after the first
    first_ms: float              # the first seed's (its kernels' compile included)

    @property
    def mean(self) -> float:
        """The gradient's mean over seeds."""
        return float(np.mean(self.grads))

    @property
    def bias(self) -> float:
        """Mean minus truth, in the loss's unit per the parameter's."""
        return self.mean - self.truth

    @property
    def standard_error(self) -> float:
        """The standard error of the mean over seeds."""
        return float(np.std(self.grads, ddof=1) / math.sqrt(len(self.grads)))

    @property
    def rel_rms_error(self) -> float | None:
        """sqrt(mean over seeds of (gradient - truth)^2) / |truth|: one gradient's typical error (None: zero truth)."""
        if self.truth == 0.0:
            return None
        return float(np.sqrt(np.mean((np.asarray(self.grads) - self.truth) ** 2))) / abs(self.truth)


@dataclass
class EqualErrorRow:
    """One technique against one integrator's curve: the spp and ms of equal error, the time ratio."""
    technique: str
    param: str
    integrator: str
    ad: float                    # the technique's derivative over the seen pixels
    truth: float
    error: float | None          # its relative error against the truth
    ms: float
    spp: float | None            # path tracing's spp at that error (None: see status)
    pt_ms: float | None
    status: str

    @property
    def time_ratio(self) -> float | None:
        """Path tracing's ms at equal error over the technique's (None where undefined)."""
        return None if self.pt_ms is None or self.ms <= 0.0 else self.pt_ms / self.ms


def crossing(spps, errors, target) -> tuple:
    """(spp, status): where the error curve (errors at increasing spps) first falls to ``target``, by linear
    interpolation of log error in log spp between the bracketing counts (REACHED); the first count with
    BELOW where its error is at or below the target already (an upper bound); None with NEVER where the
    last count's is still above it, or UNDEFINED where the target or an error is undefined."""
    if target is None or any(e is None for e in errors):
        return None, UNDEFINED
    for i, e in enumerate(errors):
        if e <= target:
            if i == 0:
                return float(spps[0]), BELOW
            e0, s0, s1 = errors[i - 1], spps[i - 1], spps[i]
            if e <= 0.0 or target <= 0.0:
                return float(s1), REACHED
            t = (math.log(target) - math.log(e0)) / (math.log(e) - math.log(e0))
            return math.exp(math.log(s0) + t * (math.log(s1) - math.log(s0))), REACHED
    return None, NEVER


def ms_at(spps, ms, spp: float) -> float:
    """Path tracing's ms per gradient at ``spp``, interpolated linearly in log-log between the measured counts."""
    return float(math.exp(np.interp(math.log(spp), np.log(np.asarray(spps, float)), np.log(np.asarray(ms, float)))))


def curve(problem, integrator: str, param: str, ref, measured=None) -> list:
    """The integrator's SppPoint at each spp of the spec's sweep, against the reference masked to its seen pixels
    (``measured``, a ProjectiveResult of this integrator and parameter, serves the count it was measured at)."""
    spec = problem.spec
    out = []
    for spp in spec.equal_error_spp:
        seeds = spec.equal_error_seeds
        reuse = reusable(measured, spp, seeds)
        res = measured if reuse else projective.gradient(problem, integrator, param, spp, seeds)
        truth = ref.masked(res.seen)
        out.append(SppPoint(integrator, param, spp, res.grads, truth.value, truth.error, res.ms, res.first_ms))
    return out


def reusable(res, spp: int, seeds: int) -> bool:
    """Whether a ProjectiveResult is the gradient at ``spp`` over ``seeds`` seeds: the same seeds 0..seeds-1 give
    the same renders, so --compare's projective run at a count of the sweep is not rendered twice."""
    return res is not None and res.spp == spp and len(res.grads) == seeds


def agrees(points) -> bool:
    """Whether the curve's last (most samples) mean is within three combined errors of the truth."""
    p = points[-1]
    return abs(p.bias) <= 3.0 * (p.standard_error + p.truth_error)


def masked_ad(problem, row, seen: np.ndarray) -> float:
    """A technique's derivative of the loss over the ``seen`` pixels, from its per-pixel tangent (CompareRow)."""
    dv = np.where(seen, row.image, 0.0).ravel()
    return problem.loss_tangent(np.zeros_like(dv), dv) + 0.0


def rows(problem, compare_rows, points, seen: np.ndarray) -> list:
    """Each technique's EqualErrorRow against one integrator's curve ``points`` (one parameter)."""
    param, integrator = points[0].param, points[0].integrator
    spps = [p.spp for p in points]
    errors = [p.rel_rms_error for p in points]
    good = agrees(points)
    out = []
    for r in compare_rows:
        if r.param != param:
            continue
        ad = masked_ad(problem, r, seen)
        err = relative(ad, points[0].truth)
        spp, status = crossing(spps, errors, err) if good else (None, DISAGREES)
        pt_ms = ms_at(spps, [p.ms for p in points], spp) if spp is not None else None
        out.append(EqualErrorRow(r.technique, param, integrator, ad, points[0].truth, err, r.ms, spp, pt_ms, status))
    return out
