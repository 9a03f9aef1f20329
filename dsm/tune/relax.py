"""The relaxed objective: a sigmoid of each receiver's signed margin over a texel-tied temperature."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from ..maps import lookup
from .. import pipeline as pl
from ..schemes.base import no_shift
from ..core.types import Length
from .evaluate import count


CLIP = 30.0              # |margin / T| beyond which the sigmoid is flat (its derivative below 1e-13)


# ---------------------------------------------------------------- the relaxed loss

def bilinear_tap(rx, smap):
    """The nearest tap with z1 and the slope layer (where the map has one) interpolated between
    the four texel centres around the receiver's map position (each read as the nearest lookup
    would read that texel: clamped to the face, the far bound beyond a directional map), so the
    margin is continuous in the lookup point. A slope read at the nearest texel would jump where
    the point crosses a texel's edge: AD sees no jump, a finite difference does (combined's
    normal offset differed from its central difference by 19 % on the meshes with it)."""
    x, y = rx.u_map - 0.5, rx.v_map - 0.5
    i0, j0 = dr.floor(dr.detach(x)), dr.floor(dr.detach(y))
    fx, fy = x - i0, y - j0
    z, slope = 0, 0
    for a in (0, 1):
        for b in (0, 1):
            t = lookup.tap_at(rx, smap, i0 + 0.5 + a, j0 + 0.5 + b)
            w = (fx if a else 1.0 - fx) * (fy if b else 1.0 - fy)
            z = z + w * t.z1
            slope = slope + w * t.slope if t.slope is not None else None
    return dataclasses.replace(lookup.nearest_tap(rx, smap), z1=z, slope=slope)


def _resolved(module, params, values: dict, rx):
    """The lookup's resolved parameters (``lookup.resolve``) with the tuned ones replaced by the
    differentiable ``values`` (name -> scalar Float in the parameter's own unit)."""
    ns = vars(lookup.resolve(params, rx)).copy()
    for name, val in values.items():
        cur = getattr(params, name)
        if isinstance(cur, Length):
            if cur.unit == "texel":
                val = val * rx.texel_world
            elif cur.unit == "range":
                val = val * dr.opaque(mi.Float, rx.view.depth_range)
        ns[name] = val
    return SimpleNamespace(**ns)


def margins(module, params, values, rx, smap, relax: bool):
    """The scheme's signed margin per receiver with ``values`` substituted (differentiable);
    ``relax``: z1 and slope read bilinearly (for parameters that move the lookup point)."""
    prm = _resolved(module, params, values, rx)
    rx2 = module.shift(rx, prm)
    tap = bilinear_tap(rx2, smap) if relax else lookup.nearest_tap(rx2, smap)
    return module.margin(rx2, tap, prm)


def relaxed_sum(m, rx, v_star_dr, t_texels, lam, weight=None):
    """sum over truly lit (1 - s) + lambda sum over truly shadowed s, s = sigmoid(m / T),
    T = t texel_world (a Dr.Jit scalar)."""
    x = dr.clip(m / (t_texels * rx.texel_world), -CLIP, CLIP)
    s = 1.0 / (1.0 + dr.exp(-x))
    per = dr.select(v_star_dr, 1.0 - s, lam * s)
    if weight is not None:
        per = per * weight
    return dr.sum(per)


def relaxed_loss(module, params, values, cases, groups, t_texels, lam, weights=None):
    """The relaxed objective over ``cases`` (a Dr.Jit scalar with the graph to ``values``)."""
    relax = module.shift is not no_shift and any(
        k in values for k in ("offset", "normal_offset"))
    culling = pl.culling_of(params)
    count("relaxed")
    total, n = 0.0, 0
    t = dr.opaque(mi.Float, float(t_texels))
    for i, c in enumerate(cases):
        smap = groups[c.group].maps[culling]
        m = margins(module, params, values, c.rx, smap, relax)
        w = None if weights is None else weights[i]
        total = total + relaxed_sum(m, c.rx, c.v_star_dr, t, lam, w)
        n += c.n            # a batch's weights are 1 / batch on the drawn receivers: the same expectation
    return total / max(n, 1), relax


def relaxed_loss_np(module, params, values: dict, cases, groups, t_texels, lam) -> float:
    """The same relaxed loss computed from the kit's forward margins in numpy float64 (the
    finite-difference tests' second computation)."""
    vals = {k: mi.Float(float(v)) for k, v in values.items()}
    relax = module.shift is not no_shift and any(k in vals for k in ("offset", "normal_offset"))
    culling = pl.culling_of(params)
    total, n = 0.0, 0
    for c in cases:
        m = margins(module, params, vals, c.rx, groups[c.group].maps[culling], relax)
        x = np.asarray(m.numpy(), np.float64) / (t_texels * np.asarray(c.rx.texel_world.numpy(), np.float64))
        x = np.clip(x, -CLIP, CLIP)
        s = 1.0 / (1.0 + np.exp(-x))
        total += float(np.where(c.v_star, 1.0 - s, lam * s).sum())
        n += c.n
    return total / max(n, 1)
