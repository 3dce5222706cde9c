"""The short-lived obstacle layer's eyes: a depth image to marked and cleared cells.

`depth_points` back-projects every `stride`-th pixel (`t = K⁻¹ [u v 1]ᵀ d`) to the world
through `T_world_base · T_base_camera`. Points between `min_height_m` and `max_height_m`
(not the floor, not above the robot) within `max_range_m` mark their cells, except cells
already in the static map and those under the robot's own footprint. Clearing: a marked
cell whose centre (at two heights) projects into the image with a measured depth beyond
it by `see_through_m` has been seen through, and is forgotten.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint


@dataclass(frozen=True)
class DepthParams:
    stride: int = 4
    min_height_m: float = 0.08
    max_height_m: float = 1.8
    max_range_m: float = 4.0
    see_through_m: float = 0.15


@dataclass(frozen=True)
class Camera:
    """Intrinsics (px) and `T_world_camera` (4, 4) of one depth frame (H, W metres)."""

    fx: float
    fy: float
    cx: float
    cy: float
    T_world_camera: NDArray[np.float64]
    depth: NDArray[np.float32]


def depth_points(cam: Camera, p: DepthParams) -> NDArray[np.float64]:
    """World points (n, 3) of the valid sampled pixels."""
    d = cam.depth[:: p.stride, :: p.stride].astype(np.float64)
    v, u = np.mgrid[0 : cam.depth.shape[0] : p.stride, 0 : cam.depth.shape[1] : p.stride]
    ok = (d > 0) & (d < p.max_range_m) & np.isfinite(d)
    z = d[ok]
    pts = np.stack([(u[ok] - cam.cx) / cam.fx * z, (v[ok] - cam.cy) / cam.fy * z, z], axis=1)
    R, t = cam.T_world_camera[:3, :3], cam.T_world_camera[:3, 3]
    out: NDArray[np.float64] = pts @ R.T + t
    return out


def obstacle_cells(
    cam: Camera, grid: Grid, pose: Pose, fp: Footprint, p: DepthParams
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Cells (iy, ix) to mark from one frame."""
    pts = depth_points(cam, p)
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
    cam: Camera, grid: Grid, iy: NDArray[np.int64], ix: NDArray[np.int64], p: DepthParams
) -> NDArray[np.bool_]:
    """Which of the cells (iy, ix) the frame sees past (at both test heights)."""
    if not len(iy):
        return np.zeros(0, dtype=bool)
    xy = grid.centres(np.stack([iy, ix], axis=1))
    T_cw = np.linalg.inv(cam.T_world_camera)
    h, w = cam.depth.shape
    through = np.ones(len(iy), dtype=bool)
    for height in (0.15, 0.5):
        pw = np.column_stack([xy, np.full(len(xy), height)])
        pc = pw @ T_cw[:3, :3].T + T_cw[:3, 3]
        z = pc[:, 2]
        zs = np.where(z > 0.05, z, 1.0)
        u = np.rint(cam.fx * pc[:, 0] / zs + cam.cx).astype(np.int64)
        v = np.rint(cam.fy * pc[:, 1] / zs + cam.cy).astype(np.int64)
        visible = (z > 0.05) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        measured = np.zeros(len(iy))
        measured[visible] = cam.depth[v[visible], u[visible]]
        through &= visible & (measured > z + p.see_through_m)
    return through
