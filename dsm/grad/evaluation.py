"""One technique's gradient as a value: ``evaluate(ctx, case, params) -> GradResult``, beside the kit's
:func:`dsm.case.evaluation.evaluate` (ctx, case) -> CaseResult.

- ``ctx`` is the gradient problem's shared part, a :class:`dsm.grad.problem.Problem`: the scene, the
  light, the receivers (the image) and the map's settings of one GradSpec.
- ``case`` is a :class:`GradCase`: the kit's :class:`dsm.case.context.Case` (a constant-bias
  SchemeSpec with its filter, or a pre-filtered MomentSpec, in float32) and what is dsm grad's own,
  whether the map is antialiased. Each technique of a GradSpec is one case (:func:`cases`), so the
  self-check, the comparisons and ``dsm.grad.run`` evaluate the same values.
- ``params`` are the parameter values (in their units) where the gradient is taken, over the
  spec's nominal ones; the gradient is taken in every parameter of ``wrt`` (default: the spec's).

Example (a plate of side 0.5 at 0.5 under a point light at 2: d area / dh = 2 A H^2 / (H - h)^3 = 0.593)::

    import dsm.grad
    from dsm.core import env
    env.use_variant(None)                     # llvm_ad_rgb
    spec = dsm.grad.spec_of("experiments/gradient/plate_point.toml")
    ctx = dsm.grad.Problem(spec)
    case = dsm.grad.cases(spec)[3]            # pcf_bilinear aa
    res = dsm.grad.evaluate(ctx, case)
    res.grads["occluder_z"], res.units["occluder_z"]      # 0.5986, 'world^2 per world'
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import prefilter
from ..case.context import Case
from ..core.types import Length, MomentSpec, SchemeSpec
from ..schemes import constant
from . import support
from .spec import LOSS_UNITS, GradSpec
from .technique import MOMENT_TECHNIQUES, Technique

FORMAT = "float32"          # dsm grad's map holds float32 depths (Dr.Jit's attached values)


@dataclass(frozen=True)
class GradCase:
    """One technique: the kit's Case (scheme or pre-filtered instance, filter, format) and dsm grad's own
    antialias (Worchel & Alexa 2023's edge treatment of the map)."""
    case: Case
    antialias: bool = False

    @property
    def technique(self) -> Technique:
        """The technique the lookups read (dsm.grad.techniques): filter or kind, blur, antialias."""
        if self.case.prefiltered:
            return Technique(self.case.spec.name, self.case.spec.blur, self.antialias)
        return Technique(self.case.filter, 1, self.antialias)

    @property
    def label(self) -> str:
        """The case as the tables name it, e.g. ``pcf_bilinear aa``, ``vsm blur 3``."""
        return self.technique.label


@dataclass
class GradResult:
    """A case's loss (float64 sum of the float32 image), its gradient per parameter, their units, the image."""
    case: GradCase
    loss: float
    loss_unit: str
    grads: dict                 # param -> d loss / d param
    units: dict                 # param -> the gradient's unit, e.g. "world^2 per world"
    image: np.ndarray           # V per pixel (N, N), row y, column x
    evaluation: object          # dsm.grad.problem.Evaluation: the map's and the pixels' classes besides


def case_of(spec: GradSpec, tech: Technique) -> GradCase:
    """The GradCase of one of ``spec``'s techniques: its kind's default parameters, or the spec's constant bias."""
    if tech.name in MOMENT_TECHNIQUES:
        moment = MomentSpec(tech.name, prefilter.get(tech.name).Params(), blur=tech.blur)
        return GradCase(Case(tech.label, moment, moment.filter, FORMAT), tech.antialias)
    scheme = SchemeSpec(constant.NAME, constant.Params(bias=Length(spec.bias, "world")))
    return GradCase(Case(tech.label, scheme, tech.name, FORMAT), tech.antialias)


def cases(spec: GradSpec) -> tuple:
    """Every technique of ``spec`` as a GradCase, in the spec's order."""
    return tuple(case_of(spec, t) for t in spec.techniques)


def check_case(spec: GradSpec, case: GradCase):
    """A ValueError naming what of ``case`` dsm grad does not differentiate (it would be ignored)."""
    c = case.case
    if c.format != FORMAT or c.hybrid is not None:
        raise ValueError(f"dsm grad differentiates a {FORMAT} map alone, got format {c.format!r}, hybrid {c.hybrid!r}")
    if c.prefiltered:
        want = case_of(spec, case.technique).case.spec
        if c.spec != want:
            raise ValueError(f"dsm grad differentiates {c.spec.name} with its default parameters and a box blur "
                             f"(got {c.spec}, valid: {want})")
        return
    if c.filter not in support.FILTERS:
        raise ValueError(f"dsm grad has no gradient of filter {c.filter!r} (valid: {', '.join(support.FILTERS)})")
    if c.spec.name != constant.NAME or c.spec.params.bias != Length(spec.bias, "world"):
        raise ValueError(f"the problem's depth tests use a constant bias of {spec.bias:g} world, got {c.spec}")


def gradient_unit(spec: GradSpec, param: str) -> str:
    """The unit of d loss / d ``param``: the loss's unit per the parameter's."""
    return f"{LOSS_UNITS[spec.loss]} per {spec.unit(param)}"


def evaluate(ctx, case: GradCase, params: dict | None = None, wrt=None) -> GradResult:
    """``case``'s loss, image and AD gradients (forward mode, one pass per parameter of ``wrt``, default the
    spec's) on problem ``ctx`` at parameter values ``params`` (over the nominal ones)."""
    spec = ctx.spec
    check_case(spec, case)
    wrt = tuple(spec.params if wrt is None else wrt)
    ev = ctx.evaluate(case.technique, ctx.values(params), wrt)
    return GradResult(case, ev.loss, LOSS_UNITS[spec.loss], ev.grads, {p: gradient_unit(spec, p) for p in wrt},
                      ev.image, ev)
