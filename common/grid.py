"""Questions about an occupancy raster shared by the services that hold one.

A grid here is a (ny, nx) bool array of occupied cells, cell [iy, ix] spanning
`origin + (i, i + 1) × resolution` (the semantic map's and navigation's convention).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt


def occupied_near(
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    origin: tuple[float, float],
    xy: npt.ArrayLike,
    margin_m: float,
) -> npt.NDArray[np.bool_]:
    """For each point (n, 2), whether an occupied cell (its square) lies within
    `margin_m` of it. Points off the grid are not near anything."""
    pts = np.atleast_2d(np.asarray(xy, dtype=float))
    out = np.zeros(len(pts), dtype=bool)
    ny, nx = occupied.shape
    r = max(0, math.ceil(margin_m / resolution))
    for k, (x, y) in enumerate(pts):
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ix = math.floor((x - origin[0]) / resolution)
        iy = math.floor((y - origin[1]) / resolution)
        if not (0 <= ix < nx and 0 <= iy < ny):
            continue
        y0, y1, x0, x1 = max(0, iy - r), min(ny, iy + r + 1), max(0, ix - r), min(nx, ix + r + 1)
        window = occupied[y0:y1, x0:x1]
        if not window.any():
            continue
        if occupied[iy, ix]:
            out[k] = True
            continue
        cy, cx = np.nonzero(window)
        half = 0.5 * resolution
        dx = np.maximum(np.abs(origin[0] + (cx + x0 + 0.5) * resolution - x) - half, 0.0)
        dy = np.maximum(np.abs(origin[1] + (cy + y0 + 0.5) * resolution - y) - half, 0.0)
        out[k] = bool(np.min(dx * dx + dy * dy) <= margin_m * margin_m)
    return out
