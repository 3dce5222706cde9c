"""The short-lived obstacle layer's eyes: a depth image to marked and cleared cells.

Every `stride`-th pixel with a return nearer than `max_range_m` is back-projected to the
world (`common.camera`: eq. 1 through `T_world_camera = T_world_base · T_base_camera`).
Points between `min_height_m` and `max_height_m` (not the floor, not above the robot)
mark their cells, except cells already in the static map and those under the robot's own
footprint. Clearing: a marked cell whose centre (at two heights) projects into the image
with a measured depth beyond it by `see_through_m` has been seen through, and is
forgotten.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from common.camera import PinholeCamera
from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint


@dataclass(frozen=True)
class DepthParams:
    stride: int = 4
    min_height_m: float = 0.08
    max_height_m: float = 1.8
    max_range_m: float = 4.0
    see_through_m: float = 0.15


def obstacle_cells(
    cam: PinholeCamera, grid: Grid, pose: Pose, fp: Footprint, p: DepthParams
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Cells (iy, ix) to mark from one frame (the camera with its depth image)."""
    pts = cam.points_world(stride=p.stride, max_depth_m=p.max_range_m)
    keep = (pts[:, 2] > p.min_height_m) & (pts[:, 2] < p.max_height_m)
    pts = pts[keep]
    if not len(pts):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pts = pts[distance_to_footprint(pose, fp, pts[:, :2]) > 0.1]
    iy, ix, inside = grid.cells(pts[:, :2])
    iy, ix = iy[inside], ix[inside]
    new = ~grid.occupied[iy, ix]
    return iy[new], ix[new]


def seen_through(
    cam: PinholeCamera, grid: Grid, iy: NDArray[np.int64], ix: NDArray[np.int64], p: DepthParams
) -> NDArray[np.bool_]:
    """Which of the cells (iy, ix) the frame sees past (at both test heights)."""
    if not len(iy):
        return np.zeros(0, dtype=bool)
    depth = cam.depth_image()
    xy = grid.centres(np.stack([iy, ix], axis=1))
    h, w = depth.shape
    through = np.ones(len(iy), dtype=bool)
    for height in (0.15, 0.5):
        uv, z = cam.project_world(np.column_stack([xy, np.full(len(xy), height)]))
        front = z > 0.05
        u = np.rint(np.where(front, uv[:, 0], -1.0)).astype(np.int64)
        v = np.rint(np.where(front, uv[:, 1], -1.0)).astype(np.int64)
        visible = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        measured = np.zeros(len(iy))
        measured[visible] = depth[v[visible], u[visible]]
        through &= visible & (measured > z + p.see_through_m)
    return through
