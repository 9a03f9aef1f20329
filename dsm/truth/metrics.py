"""Metrics: shadow-map visibility V against exact visibility V*, per receiver.

| acne (false shadow)          | V* = 1 and V < 0.5; ``self`` when the nearest texel's first hit lies
|                              | on the receiver's own surface (its tangent plane, within the texel's
|                              | depth extent: dsm.maps.lookup.on_own_surface), ``edge``
|                              | otherwise (another surface, whatever shape holds it: an outline)
| peter-panning (false light)  | V* = 0 and V >= 0.5, with the distance to the true occluder
| acne_rate                    | n_acne / n_gt_lit
| peterpan_rate                | n_peterpan / n_gt_shadowed
| error_rate                   | (n_acne + n_peterpan) / n_receivers
| mean_abs_error               | mean |V - V*| over receivers
| seam_error_rate              | error rate of receivers within SEAM_TEXELS of a seam between
|                              | faces (cube edges, paraboloid rim); off_seam_error_rate: the rest

| n_peterpan_contact, n_leak   | peter-panning split by the receiver's distance to its exact
|                              | occluder (along the shadow ray) in texels at the receiver: within
|                              | ``leak_texels`` (contact: the occluder touches or nearly touches the
|                              | receiver) or beyond it (light leaking, the pre-filtered maps' error)
| leak_rate                    | n_leak / n_gt_shadowed; peterpan_contact_rate likewise

| backface_lit_rate            | pixels facing away from the light (attached shadow) that the map
|                              | calls lit, over those pixels: Weiskopf & Ertl's self-unshadowing, apart
|                              | from the receivers' metrics

A value without a defined meaning (a rate whose denominator is empty, the median distance
without peter-panning, seam rates on a view without seams, anything over zero receivers) is
NaN here: an empty cell in metrics.csv, a dash in tables, left out of means and plots.
"""
from __future__ import annotations

import numpy as np

from ..core.record import LEAK_COLUMNS, SOFT_COLUMNS   # the columns leak_split and soft fill

# Classes of the error image, in the order of CLASS_COLORS.
# The last two: errors the per-texel oracle makes too (the map's resolution's, no bias fixes
# them; nearest filter only), in a darker shade of their class.
# The last: with the leak split ([map] kind given), peter-panning farther than leak_texels from
# its occluder (light leaking), in its own colour.
OUTSIDE, LIT, SHADOW, ACNE, PETERPAN, ACNE_RESOLUTION, PETERPAN_RESOLUTION, LEAK = range(8)
CLASS_NAMES = ("not a receiver", "correct lit", "correct shadow", "acne", "peter-panning",
               "acne (resolution)", "peter-panning (resolution)", "light leak")
CLASS_COLORS = np.array([[0, 0, 0], [235, 225, 190], [70, 80, 110], [230, 40, 40], [40, 170, 255],
                         [120, 15, 15], [15, 80, 140], [225, 60, 215]], np.uint8)


SEAM_TEXELS = 3.0


UNDEFINED = float("nan")


def _rate(num, den) -> float:
    return float(num) / float(den) if den else UNDEFINED


def defined(x) -> bool:
    """Whether a metric value has a meaning (is not the undefined NaN)."""
    return not (isinstance(x, float) and x != x)


def compute(v: np.ndarray, v_star: np.ndarray, own: np.ndarray, occluder_dist: np.ndarray,
            seam_dist: np.ndarray | None = None, has_seams: bool | None = None) -> dict:
    """All metrics of one case from per-receiver arrays (``own``: the nearest texel's first hit is on
    the receiver's own surface; ``seam_dist``: texels to a face seam; ``has_seams``: whether the
    view has seams at all, else told by finite seam distances)."""
    v = np.asarray(v, np.float64)
    v_star = np.asarray(v_star, bool)
    shadowed_v = v < 0.5
    acne = v_star & shadowed_v
    peter = ~v_star & ~shadowed_v
    acne_self = acne & np.asarray(own, bool)
    n = int(v.size)
    n_lit, n_shadow = int(v_star.sum()), int((~v_star).sum())
    n_acne, n_peter = int(acne.sum()), int(peter.sum())
    dist = occluder_dist[peter]
    dist = dist[np.isfinite(dist)]
    err = acne | peter
    seam_dist = None if seam_dist is None else np.asarray(seam_dist)
    if has_seams is None:
        has_seams = seam_dist is not None and bool(np.isfinite(seam_dist).any())
    if seam_dist is None:
        seam_dist = np.full(n, np.inf)
    near = np.zeros(n, bool) if not has_seams else seam_dist < SEAM_TEXELS
    return {
        "n_receivers": n, "n_gt_lit": n_lit, "n_gt_shadowed": n_shadow,
        "n_acne": n_acne, "n_acne_self": int(acne_self.sum()), "n_acne_edge": int(n_acne - acne_self.sum()),
        "n_peterpan": n_peter,
        "acne_rate": _rate(n_acne, n_lit), "peterpan_rate": _rate(n_peter, n_shadow),
        "error_rate": _rate(n_acne + n_peter, n),
        "mean_abs_error": float(np.abs(v - v_star).mean()) if n else UNDEFINED,
        "peterpan_dist_median": float(np.median(dist)) if dist.size else UNDEFINED,
        "n_seam": int(near.sum()) if has_seams else UNDEFINED,
        "seam_error_rate": _rate((err & near).sum(), near.sum()) if has_seams else UNDEFINED,
        "off_seam_error_rate": _rate((err & ~near).sum(), (~near).sum()) if has_seams else UNDEFINED,
    }




def leak_split(v, v_star, deep) -> dict:
    """A case's peter-panning (V* = 0, V >= 0.5) split by where it is in the exact shadow: *edge*
    within leak_texels texels of an exactly lit point of the receiver's own surface, *leak* deeper
    inside (``deep``: :func:`dsm.pipeline.deep_in_shadow` per receiver; None, an area light's
    soft shadow: undefined). The two add up to n_peterpan; their rates are over n_gt_shadowed
    (NaN where nothing is shadowed)."""
    if deep is None:
        return {k: UNDEFINED for k in LEAK_COLUMNS}
    v_star = np.asarray(v_star, bool)
    peter = ~v_star & (np.asarray(v, np.float64) >= 0.5)
    leak = leak_mask(v, v_star, deep)
    n_edge, n_leak, n_shadow = int((peter & ~leak).sum()), int(leak.sum()), int((~v_star).sum())
    return {"n_peterpan_edge": n_edge, "n_leak": n_leak,
            "peterpan_edge_rate": _rate(n_edge, n_shadow), "leak_rate": _rate(n_leak, n_shadow)}


def leak_mask(v, v_star, deep) -> np.ndarray:
    """The receivers that leak: peter-panned (V* = 0, V >= 0.5) and deep in the exact shadow."""
    peter = ~np.asarray(v_star, bool) & (np.asarray(v, np.float64) >= 0.5)
    return peter & np.asarray(deep, bool)


def classify(v, v_star, resolution=None, leak=None) -> np.ndarray:
    """Per-receiver class (LIT, SHADOW, ACNE, PETERPAN; with ``resolution``, the receivers the
    per-texel oracle gets wrong too, errors are ACNE_RESOLUTION and PETERPAN_RESOLUTION; with
    ``leak``, a leak_mask, the leaking peter-panned receivers are LEAK)."""
    v_star = np.asarray(v_star, bool)
    lit = np.asarray(v) >= 0.5
    out = np.where(v_star, np.where(lit, LIT, ACNE), np.where(lit, PETERPAN, SHADOW)).astype(np.uint8)
    if resolution is not None:
        res = np.asarray(resolution, bool)
        out[(out == ACNE) & res] = ACNE_RESOLUTION
        out[(out == PETERPAN) & res] = PETERPAN_RESOLUTION
    if leak is not None:
        out[np.asarray(leak, bool)] = LEAK
    return out


def base_class(classes) -> np.ndarray:
    """Classes with the resolution-limited errors and the leaks folded into acne and peter-panning."""
    c = np.asarray(classes)
    return np.where(c == ACNE_RESOLUTION, ACNE, np.where(np.isin(c, (PETERPAN_RESOLUTION, LEAK)), PETERPAN,
                                                         c)).astype(c.dtype)


SPLIT_COLUMNS = ("n_acne_resolution", "n_acne_bias", "n_peterpan_resolution", "n_peterpan_bias")


def split(v, v_star, resolution=None) -> dict:
    """A case's errors split into ``resolution`` (the per-texel oracle gets the receiver wrong
    too) and ``bias`` (the rest). Undefined (NaN) without ``resolution`` (filters other than
    nearest: the oracles are those of a nearest lookup)."""
    if resolution is None:
        return {k: UNDEFINED for k in SPLIT_COLUMNS}
    v_star = np.asarray(v_star, bool)
    lit = np.asarray(v) >= 0.5
    res = np.asarray(resolution, bool)
    acne, peter = v_star & ~lit, ~v_star & lit
    return {"n_acne_resolution": int((acne & res).sum()), "n_acne_bias": int((acne & ~res).sum()),
            "n_peterpan_resolution": int((peter & res).sum()), "n_peterpan_bias": int((peter & ~res).sum())}


SOFT_REGIONS = ("umbra", "penumbra", "lit")


def soft(v, hits, samples, half, own) -> dict:
    """Soft-shadow metrics of V in [0, 1] against an area light's reference V* = hits / samples.

    Regions by the reference's samples: umbra (none visible, V* = 0), penumbra (0 < V* < 1),
    lit (all visible, V* = 1). ``mean_abs_error`` and ``rmse`` of V - V* over all receivers and
    per region (``mae_<region>``, ``rmse_<region>``; NaN over an empty region). Acne and
    peter-panning keep their meaning where V* is 0 or 1: acne = lit and V < 0.5 (over the lit
    receivers: ``acne_rate``), peter-panning = umbra and V >= 0.5 (over the umbra); penumbra
    receivers count in neither. The reference's own uncertainty: the mean and largest
    half-width of its interval (at the light's confidence) and the mean samples per receiver, to tell the kit's error from the reference's
    noise. ``own``: per receiver, the acne split's ``self`` (as in :func:`compute`)."""
    v = np.asarray(v, np.float64)
    hits, samples = np.asarray(hits), np.asarray(samples)
    v_star = hits / np.maximum(samples, 1)
    err = v - v_star
    umbra, lit = hits == 0, hits == samples
    pen = ~umbra & ~lit
    n = int(v.size)
    acne = lit & (v < 0.5)
    peter = umbra & (v >= 0.5)
    acne_self = acne & np.asarray(own, bool)
    out = {"n_gt_lit": int(lit.sum()), "n_gt_shadowed": int(umbra.sum()), "n_acne": int(acne.sum()),
           "n_acne_self": int(acne_self.sum()), "n_acne_edge": int(acne.sum() - acne_self.sum()),
           "n_peterpan": int(peter.sum()), "acne_rate": _rate(acne.sum(), lit.sum()),
           "peterpan_rate": _rate(peter.sum(), umbra.sum()), "error_rate": _rate(acne.sum() + peter.sum(), n),
           "mean_abs_error": float(np.abs(err).mean()) if n else UNDEFINED,
           "rmse": float(np.sqrt((err ** 2).mean())) if n else UNDEFINED,
           "peterpan_dist_median": UNDEFINED,
           "ref_half_width_mean": float(np.mean(half)) if n else UNDEFINED,
           "ref_half_width_max": float(np.max(half)) if n else UNDEFINED,
           "ref_samples_mean": float(np.mean(samples)) if n else UNDEFINED}
    for name, sel in zip(SOFT_REGIONS, (umbra, pen, lit)):
        out[f"n_{name}"] = int(sel.sum())
        out[f"mae_{name}"] = float(np.abs(err[sel]).mean()) if sel.any() else UNDEFINED
        out[f"rmse_{name}"] = float(np.sqrt((err[sel] ** 2).mean())) if sel.any() else UNDEFINED
    return out
