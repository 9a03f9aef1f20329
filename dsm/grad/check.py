"""Self-checks of the gradients, before any comparison with the truth.

- **AD against the technique's own central differences**: (L(p + s) - L(p - s)) / 2s, where no
  texel (the shape its ray hits), for nearest and PCSS no pixel (its result and the texel it
  reads), and for an antialiased map no texel pair (whether the edge treatment treats it: a
  corner's pair switches on and off while no texel changes class) changes between p - s, p and
  p + s; the step is halved (``fd_halvings`` times at most) until none does, and a row whose
  structure still changes says so (its difference then measures a jump, not a slope, and AD
  against it is undefined).
- **Closed forms** of the plate scene (ground at z = 0, square plate of area A at height h):
  under a point light at height H the shadow is the plate scaled by H / (H - h), so its area
  A H^2 / (H - h)^2 has d/dh = 2 A H^2 / (H - h)^3 and d/dH = -2 A H h / (H - h)^3, and its first
  moment in x, area times centre, has d/dx_occluder = A H^3 / (H - h)^3 and d/dx_light =
  -A H^2 h / (H - h)^3; under a directional light
  tilted by theta toward +x every plate point lands h tan(theta) further along x, so the area is
  constant (derivatives 0) and the first moment A (x_c + h tan theta) has d/dtheta = A h / cos^2
  theta (per radian; the table's angles are in degrees), d/dh = A tan theta, d/dx = A.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .evaluation import cases, evaluate
from .spec import LOSS_UNITS


@dataclass
class CheckRow:
    """One technique and parameter: AD, central difference, closed form (None where none exists)."""
    technique: str
    param: str
    unit: str
    loss: float
    ad: float
    fd: float
    step: float
    changed_texels: int          # texels whose class differs between p - step and p + step
    changed_pixels: int
    closed_form: float | None
    edge_pairs: int
    changed_pairs: int = 0       # texels whose antialiasing pairs differ between p - step and p + step

    @property
    def clean(self) -> bool:
        """Whether no texel, pixel or antialiasing pair changed within +-step (the difference is a slope)."""
        return self.changed_texels == 0 and self.changed_pixels == 0 and self.changed_pairs == 0

    @property
    def ad_vs_fd(self) -> float | None:
        """|AD - FD| / |FD|; None where FD is 0 (undefined) or classes changed."""
        return relative(self.ad, self.fd) if self.clean else None

    @property
    def ad_vs_closed(self) -> float | None:
        """|AD - closed form| / |closed form|; None without a closed form or where it is 0."""
        return None if self.closed_form is None else relative(self.ad, self.closed_form)


def relative(a: float, ref: float) -> float | None:
    """|a - ref| / |ref|, None where ref is 0 (an empty denominator) or not finite."""
    if not math.isfinite(ref) or ref == 0.0:
        return None
    return abs(a - ref) / abs(ref)


def relative_within(a: float, ref: float, ref_error: float) -> float | None:
    """|a - ref| / |ref|, None where |ref| is within its own error of 0 (a truth of 0 +- its error has no
    scale to divide by: 0.00095 +- 0.0025 made an error of 5237 %)."""
    if not abs(ref) > ref_error:
        return None
    return relative(a, ref)


def closed_form(spec, param: str) -> float | None:
    """The exact d loss / d param of the plate scene (in the loss's unit per the parameter's unit), None where
    the kit knows none (the box, the l2 loss, a vertex's displacement, an area light: its soft shadow's
    derivative is a numerical integral, tests/test_grad_area.py)."""
    if spec.scene != "plate" or spec.loss == "l2" or param == "corner_z" or spec.light == "area":
        return None
    A, h = spec.occluder_size ** 2, spec.occluder_height
    area = spec.loss == "shadow_area"
    if spec.light == "point":
        H = spec.light_height
        forms = {"occluder_z": (2 * A * H ** 2 / (H - h) ** 3, None),
                 "light_height": (-2 * A * H * h / (H - h) ** 3, None),
                 "occluder_x": (0.0, A * H ** 3 / (H - h) ** 3),
                 "light_x": (0.0, -A * H ** 2 * h / (H - h) ** 3)}   # the centre moves by -h / (H - h)
        a, m = forms[param]
        return a if area else m
    t = math.radians(spec.light_angle)
    forms = {"light_angle": (0.0, A * h / math.cos(t) ** 2 * math.pi / 180.0),
             "occluder_z": (0.0, A * math.tan(t)), "occluder_x": (0.0, A)}
    a, m = forms[param]
    return a if area else m


def _classes(problem, tech, values):
    """(texel classes, pixel classes, pair classes): the shape each texel's ray hits; for the techniques with
    a step in the receiver's map position (nearest; PCSS, whose blocker search reads nearest taps) each
    pixel's nearest result and the texel it reads (PCSS's search taps sit at other texels: a lower bound);
    for an antialiased map which of each texel's pairs the edge treatment treats. The others are continuous
    where a receiver crosses between texels: their pixels have no class."""
    ev = problem.evaluate(type(tech)("nearest"), values)
    pixels = ev.image.ravel() + 2.0 * ev.pixel_texels if tech.name in ("nearest", "pcss") else np.zeros(1)
    pairs = np.zeros(1, np.uint8)
    if tech.antialias:
        pairs = problem.evaluate(type(tech)("nearest", antialias=True), values).edge_structure
    return ev.texel_shapes, pixels, pairs


def central_difference(problem, tech, param: str) -> tuple:
    """(FD, step, texels changed, pixels changed, pairs changed) of ``tech``'s loss in ``param``, halving the
    step until no class changes within +-step (at most ``fd_halvings`` times)."""
    spec = problem.spec
    base = problem.values()
    step = spec.step(param)
    c0 = _classes(problem, tech, base)
    for k in range(spec.fd_halvings + 1):
        lo, hi = dict(base), dict(base)
        lo[param] -= step
        hi[param] += step
        cl, ch = _classes(problem, tech, lo), _classes(problem, tech, hi)
        texels, pixels, pairs = (int(np.count_nonzero((a != o) | (b != o))) for a, b, o in zip(cl, ch, c0))
        if (texels == 0 and pixels == 0 and pairs == 0) or k == spec.fd_halvings:
            break
        step /= 2.0
    fd = (problem.evaluate(tech, hi).loss - problem.evaluate(tech, lo).loss) / (2.0 * step)
    return fd, step, texels, pixels, pairs


def self_check(problem, progress=None) -> list:
    """Every technique (one case each, dsm.grad.evaluate) of the spec against its own central differences and
    the closed forms, per parameter."""
    spec = problem.spec
    rows = []
    for case in cases(spec):
        res = evaluate(problem, case)
        for p in spec.params:
            fd, step, texels, pixels, pairs = central_difference(problem, case.technique, p)
            rows.append(CheckRow(case.label, p, spec.unit(p), res.loss, res.grads[p], fd, step, texels, pixels,
                                 closed_form(spec, p), res.evaluation.edge_pairs, pairs))
            if progress:
                progress(rows[-1])
    return rows


def loss_unit(spec) -> str:
    """The loss's unit (world lengths to a power, or 1)."""
    return LOSS_UNITS[spec.loss]
