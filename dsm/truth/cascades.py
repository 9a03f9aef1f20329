"""A cascaded map's metrics per case: per cascade (receivers, acne, peter-panning, texels per
camera pixel) and the error against distance from the camera (the curve of plots/cascades_*.png)."""
from __future__ import annotations

import numpy as np

from ..maps.cascades import CascadeView, texels_per_pixel
from . import metrics, transition


def _np3(v) -> np.ndarray:
    return np.stack([np.asarray(c.numpy(), np.float64) for c in (v.x, v.y, v.z)], axis=1)


def case_metrics(view: CascadeView, rx, v: np.ndarray, v_star: np.ndarray) -> tuple:
    """(per-case columns, per-cascade rows, distance curve, cascade index per receiver) of one case."""
    if rx is None or len(v) == 0:
        empty = transition.columns(view, np.zeros((0, 3)), np.zeros(0, int), np.zeros(0), np.zeros(0, bool))
        return {"texels_per_pixel": metrics.UNDEFINED, "fit_ms": view.fit_ms, **empty}, [], None, np.zeros(0, int)
    p, n = _np3(rx.p_world), _np3(rx.n_world)
    face = np.asarray(rx.face.numpy(), int)
    tpp = texels_per_pixel(view, p, n, face)
    dist = np.linalg.norm(p - view.camera.origin, axis=1)
    v_star = np.asarray(v_star, bool)
    lit = np.asarray(v) >= 0.5
    acne, peter = v_star & ~lit, ~v_star & lit
    rows = []
    for c in view.describe():
        k = c.get("face", c["cascade"])     # a virtual view names a level by its number, its face apart
        s = face == k
        nl, ns = int((v_star & s).sum()), int((~v_star & s).sum())
        na, npp = int((acne & s).sum()), int((peter & s).sum())
        rows.append({**c, "n_receivers": int(s.sum()), "n_acne": na, "n_peterpan": npp,
                     "acne_rate": na / nl if nl else metrics.UNDEFINED,
                     "peterpan_rate": npp / ns if ns else metrics.UNDEFINED,
                     "error_rate": (na + npp) / int(s.sum()) if s.any() else metrics.UNDEFINED,
                     "texels_per_pixel_median": float(np.median(tpp[s])) if s.any() else metrics.UNDEFINED})
    # error and texels per pixel against distance from the camera: log-spaced bins
    lo, hi = max(dist.min(), 1e-30), max(dist.max(), 1e-30)
    edges = np.geomspace(lo, hi * (1 + 1e-9), 17) if hi > lo else np.array([lo, hi * (1 + 1e-9) + 1e-30])
    b = np.clip(np.searchsorted(edges, dist, side="right") - 1, 0, len(edges) - 2)
    curve = []
    for i in range(len(edges) - 1):
        s = b == i
        if s.any():
            curve.append((float(np.sqrt(edges[i] * edges[i + 1])), float((acne | peter)[s].mean()),
                          float(np.median(tpp[s]))))
    near = transition.columns(view, p, face, tpp, acne | peter)
    return {"texels_per_pixel": float(np.median(tpp)), "fit_ms": view.fit_ms, **near}, rows, curve, face
