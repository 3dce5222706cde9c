"""The trunk lidar's ranges ray-cast exactly against axis-aligned boxes (a slab test per
box), and those boxes rasterised as the sim does: the localization's and the SLAM's tests
and `dume bench slam`."""

from __future__ import annotations

import math

import numpy as np

from common import robot

T_BASE_LIDAR = robot.LIDAR_MOUNT.T_parent_lidar
ANGLES = np.radians(np.linspace(-135.0, 135.0, 541))
Box = tuple[float, float, float, float]  # x0, y0, x1, y1


def slab_ranges(
    boxes: list[Box], pose: tuple[float, float, float], noise_m: float, rng: np.random.Generator
) -> np.ndarray:
    """Ranges from the base at `pose` to the nearest box along each beam, Gaussian noise
    `noise_m`, 0 beyond 10 m."""
    T = T_BASE_LIDAR
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    ox, oy = x + c * T[0, 3] - s * T[1, 3], y + s * T[0, 3] + c * T[1, 3]
    dx, dy = np.cos(yaw + ANGLES), np.sin(yaw + ANGLES)
    r = np.full(len(ANGLES), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, y0, x1, y1 in boxes:
            tx0, tx1 = (x0 - ox) / dx, (x1 - ox) / dx
            ty0, ty1 = (y0 - oy) / dy, (y1 - oy) / dy
            near = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            r = np.where((near <= far) & (near > 0.0), np.minimum(r, near), r)
    r = r + rng.normal(0.0, noise_m, len(r))
    return np.where(r < 10.0, r, 0.0)


def overlap_grid(
    boxes: list[Box], origin: tuple[float, float], shape: tuple[int, int], res: float
) -> np.ndarray:
    """The occupancy of axis-aligned boxes as the sim rasterises it: a cell is occupied
    when the box overlaps it (its centre lies within the box grown by half a cell)."""
    h = 0.5 * res
    xs = origin[0] + (np.arange(shape[1]) + 0.5) * res
    ys = origin[1] + (np.arange(shape[0]) + 0.5) * res
    occ = np.zeros(shape, dtype=bool)
    for x0, y0, x1, y1 in boxes:
        occ |= ((xs > x0 - h) & (xs < x1 + h))[None, :] & ((ys > y0 - h) & (ys < y1 + h))[:, None]
    return occ
