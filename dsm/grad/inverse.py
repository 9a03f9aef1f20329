"""The inverse task: recover a perturbed parameter from the exact image by descent through a technique.

The target is the exact (ray-traced) image at the configured scene; each start moves one
parameter by an offset (``inverse_starts``, in the parameter's unit) and descends the l2 loss
between the technique's image and the target with Adam (Kingma & Ba 2015; ``mi.ad.Adam``, as
dsm tune's steps) on that one parameter, its learning rate ``STEP_FRACTION`` of the largest start
offset and decaying as 1 / (1 + k / DECAY) (:func:`learning_rate`, set before each step), for
``inverse_iterations`` steps. mi.ad.Adam keeps its state in float32 with epsilon 1e-8 (the
hand-written Adam it replaced: float64, 1e-12), so the traces moved in their last digits. Per start: the final parameter error, whether it is within
``inverse_tolerance`` (success), the iteration from which the error stayed within it (None if
never), and the time to that iteration (wall clock of the whole step: evaluation, derivative,
update; ``dr.sync_thread()`` around each read, the first step's compile included, as a user meets it).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from .problem import Problem

STEP_FRACTION = 0.25
DECAY = 10.0
BETAS = (0.9, 0.999)


@dataclass
class InverseRun:
    """One technique, parameter and start: the descent's outcome against the truth."""
    technique: str
    param: str
    unit: str
    start_offset: float
    final_error: float            # |p_final - p_true| in the parameter's unit
    success: bool
    converged_at: int | None      # first iteration from which the error stayed within the tolerance
    seconds_to_converge: float | None
    seconds: float                # all iterations
    trace: tuple                  # the parameter's value after each iteration


def inverse_problem(problem, param: str) -> Problem:
    """The problem's scene with the l2 loss against its exact image at the configured values."""
    spec = dataclasses.replace(problem.spec, loss="l2", target=((param, problem.spec.nominal()[param]),))
    return Problem(spec)


def learning_rate(spec, k: int) -> float:
    """The learning rate of step ``k`` (from 0): STEP_FRACTION of the largest start offset, decaying as
    1 / (1 + k / DECAY)."""
    return STEP_FRACTION * max(abs(s) for s in spec.inverse_starts) / (1.0 + k / DECAY)


def descend(problem, tech, param: str, offset: float) -> InverseRun:
    """Adam (mi.ad.Adam) on ``param`` from the truth + ``offset``, through ``tech``'s image (``problem``'s
    loss is l2): its gradient by forward mode (Problem.evaluate), handed to the optimizer per step."""
    spec = problem.spec
    truth = spec.nominal()[param]
    opt = mi.ad.Adam(lr=learning_rate(spec, 0), beta_1=BETAS[0], beta_2=BETAS[1])
    opt[param] = mi.Float(truth + offset)
    p = truth + offset
    trace, times = [], []
    dr.sync_thread()
    t0 = time.perf_counter()
    for k in range(spec.inverse_iterations):
        g = problem.evaluate(tech, problem.values({param: p}), (param,)).grads[param]
        opt.set_learning_rate(learning_rate(spec, k))
        dr.set_grad(opt[param], mi.Float(g))
        opt.step()
        p = float(opt[param][0])
        trace.append(p)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    errors = [abs(x - truth) for x in trace]
    tol = spec.inverse_tolerance
    at = next((i for i in range(len(errors)) if all(e <= tol for e in errors[i:])), None)
    return InverseRun(tech.label, param, spec.unit(param), offset, errors[-1], errors[-1] <= tol,
                      None if at is None else at + 1, None if at is None else times[at], times[-1], tuple(trace))


def run_inverse(problem, progress=None) -> list:
    """Every technique, parameter and start of the spec: the inverse task's runs."""
    runs = []
    for param in problem.spec.params:
        inv = inverse_problem(problem, param)
        for tech in problem.spec.techniques:
            for off in problem.spec.inverse_starts:
                runs.append(descend(inv, tech, param, off))
                if progress:
                    progress(runs[-1])
    return runs


def success_rate(runs) -> float | None:
    """The fraction of runs that succeeded (None without runs)."""
    return sum(r.success for r in runs) / len(runs) if runs else None
