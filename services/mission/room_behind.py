"""How far the robot can back up before its footprint meets an obstacle the map knows.

The back-off after a handover walks the base backwards on the mission's own cmd_vel,
outside navigation's costmap: at a person standing near a wall it walked the rear thigh
into the wall (hall seed 1 explored: three contacts with `wall_8` during the back-off).
`room_behind` sweeps the footprint's rear edge (`common.robot.FOOTPRINT_BOUNDS`, the arm
stowed; the arm reaches forward, not back) backwards over the map's grid and returns the
distance to the first occupied cell, less `margin_m`, at most `want_m` (`occupied_rows`:
the grid seen from the base, row by row; the stow's edge ahead, `stow_room`, too). Pure
numpy.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from common.robot import FOOTPRINT_BOUNDS

OCCUPIED = 100
#: Kept between the footprint's rear edge and the nearest obstacle, m.
MARGIN_M = 0.05


def room_behind(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    xy: tuple[float, float],
    yaw: float,
    want_m: float,
    margin_m: float = MARGIN_M,
    bounds: tuple[float, float, float, float] = FOOTPRINT_BOUNDS,
) -> float:
    """Metres the base at (xy, yaw) can move straight back, in [0, want_m]."""
    x_min, _, y_min, y_max = bounds
    step = resolution_m / 2.0
    back = np.arange(0.0, want_m + margin_m + step, step)  # behind the rear edge
    across = np.arange(y_min - margin_m, y_max + margin_m + step / 2, step)
    hit = occupied_rows(cells, resolution_m, origin_xy, xy, yaw, x_min - back, across)
    rows = np.nonzero(hit)[0]
    if len(rows) == 0:
        return want_m
    first = float(back[rows[0]])  # the nearest obstacle behind the rear edge
    return float(min(want_m, max(0.0, first - margin_m)))


def occupied_rows(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    xy: tuple[float, float],
    yaw: float,
    along: NDArray[np.float64],
    across: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """For each x of `along` (m, the frame of a base at (xy, yaw)), whether the grid has
    an occupied cell at (x, y) for some y of `across` (cells off the grid are free)."""
    bx, by = np.meshgrid(along, across, indexing="ij")
    c, s = math.cos(yaw), math.sin(yaw)
    ix = np.floor((xy[0] + c * bx - s * by - origin_xy[0]) / resolution_m).astype(np.intp)
    iy = np.floor((xy[1] + s * bx + c * by - origin_xy[1]) / resolution_m).astype(np.intp)
    h, w = cells.shape
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    hit = np.zeros(bx.shape, bool)
    hit[inside] = cells[iy[inside], ix[inside]] == OCCUPIED
    return np.asarray(hit.any(axis=1), dtype=bool)
