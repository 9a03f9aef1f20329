"""Where a cascaded or virtual map changes cascade or level: each receiver's distance to the nearest
transition of the selection that chose its cascade (its level), in texels of the map it reads, the
errors within a few texels of it, and the spread of texels per camera pixel.

A cascaded view selects by the camera's view depth against its split distances; a virtual view by
the receiver's distance to the camera against its levels' distance ranges
(:meth:`dsm.maps.virtual.VirtualView.distance_range`). A receiver's transition distance is how far
that measure is from the nearer bound of its own range (world units: the length a receiver must move
along the view axis, or toward the camera, to change maps), over its map's texel; the first range's
near bound and the last's far bound are no transition (nothing is selected beyond them).
"""
from __future__ import annotations

import math

import numpy as np

from . import metrics

TRANSITION_TEXELS = 4.0     # "near a transition": within this many texels of the map read


def selection_measure(view, p: np.ndarray) -> np.ndarray:
    """What the view's selection reads at world points ``p`` (float64): the distance to the camera
    (virtual) or the camera's view depth (cascaded)."""
    d = np.asarray(p, float) - np.asarray(view.camera.origin, float)
    if view.virtual:
        return np.linalg.norm(d, axis=1)
    return d @ np.asarray(view.camera.forward, float)


def selection_bounds(view) -> tuple:
    """(lo, hi) per face of the selection's ranges, -inf / inf where a bound is no transition."""
    n = view.faces
    if view.virtual:
        lo, hi = (np.array(b, float) for b in zip(*(view.distance_range(k) for k in range(n))))
    else:
        s = np.asarray(view.splits, float)
        lo, hi = s[:-1].copy(), s[1:].copy()
    lo[0], hi[-1] = -math.inf, math.inf
    return lo, hi


def transition_texels(view, p: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Per receiver: the distance from its selection measure to the nearer transition of its face's
    range, in texels of that face (inf where its face has no transition: a single map)."""
    face = np.asarray(face, int)
    x = selection_measure(view, p)
    lo, hi = selection_bounds(view)
    texel = np.asarray(view.extents, float)[face] / view.resolution
    with np.errstate(invalid="ignore"):
        gap = np.minimum(np.abs(x - lo[face]), np.abs(hi[face] - x))
    return gap / texel


def columns(view, p: np.ndarray, face: np.ndarray, tpp: np.ndarray, wrong: np.ndarray) -> dict:
    """metrics.csv's transition columns: texels per pixel's 10th and 90th percentiles and the share
    below 1, the receivers within TRANSITION_TEXELS of a transition and the error rates on and off them."""
    tpp, wrong = np.asarray(tpp, float), np.asarray(wrong, bool)
    near = transition_texels(view, p, face) <= TRANSITION_TEXELS if len(tpp) else np.zeros(0, bool)
    rate = lambda s: float(wrong[s].mean()) if s.any() else metrics.UNDEFINED
    if not len(tpp):
        q10 = q90 = below = metrics.UNDEFINED
    else:
        q10, q90 = (float(q) for q in np.percentile(tpp, [10, 90]))
        below = float((tpp < 1.0).mean())
    return {"tpp_p10": q10, "tpp_p90": q90, "tpp_below_1": below, "n_transition": int(near.sum()),
            "transition_error_rate": rate(near), "off_transition_error_rate": rate(~near)}
