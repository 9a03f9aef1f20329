"""A real terrain in metres, from the digital elevation model that matplotlib ships.

``jacksboro_fault_dem.npz`` (matplotlib's sample data, ``matplotlib.cbook.get_sample_data``):
344 x 403 elevations in metres (236 to 1076) on a 3-arc-second grid (dx = dy = 1/1200 degree)
over the Jacksboro fault, Tennessee (36.45 to 36.73 N, 84.08 to 84.41 W). The grid is placed on
a plane by the equirectangular projection about its centre latitude (metres per degree from the
mean Earth radius, longitude scaled by cos(latitude)): about 74.5 m by 92.6 m per cell, 30.0 x
31.8 km in all, distances within 0.1 % of the geodesic ones at this size. x points east, y north,
z up; x and y are centred on the grid's centre, z is the elevation above sea level (the scene
does not sit at the origin: part of what must hold). Each grid cell is two triangles wound
counter-clockwise seen from above. Credit and terms: data/meshes/README.md.
"""
from __future__ import annotations

import functools
import math

import numpy as np

EARTH_RADIUS_M = 6371008.8          # mean Earth radius (IUGG)
SAMPLE = "jacksboro_fault_dem.npz"


def _dem() -> dict:
    """The DEM's arrays as numpy (elevation in metres, spacing and bounds in degrees)."""
    from matplotlib import cbook
    with np.load(cbook.get_sample_data(SAMPLE, asfileobj=False)) as d:
        return {k: np.asarray(d[k]) for k in d.files}


@functools.lru_cache(maxsize=4)
def mesh(stride: int = 1) -> tuple:
    """(vertices (n, 3) float64 in metres, faces (m, 3) int64) of every ``stride``-th DEM sample."""
    d = _dem()
    z_m = d["elevation"].astype(np.float64)[::stride, ::stride]
    rows, cols = z_m.shape
    lat0 = math.radians((float(d["ymin"]) + float(d["ymax"])) / 2)
    m_per_deg = EARTH_RADIUS_M * math.pi / 180
    dx_m = float(d["dx"]) * stride * m_per_deg * math.cos(lat0)
    dy_m = float(d["dy"]) * stride * m_per_deg
    x_m = (np.arange(cols) - (cols - 1) / 2) * dx_m
    y_m = ((rows - 1) / 2 - np.arange(rows)) * dy_m             # row 0 north, as matplotlib's examples draw it
    xx, yy = np.meshgrid(x_m, y_m)
    verts = np.stack([xx.ravel(), yy.ravel(), z_m.ravel()], axis=1)
    k = np.arange(rows * cols).reshape(rows, cols)
    nw, ne, sw, se = k[:-1, :-1].ravel(), k[:-1, 1:].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel()
    # counter-clockwise seen from above (+z): sw -> se -> ne and sw -> ne -> nw
    faces = np.concatenate([np.stack([sw, se, ne], 1), np.stack([sw, ne, nw], 1)])
    return verts, faces
