"""The short-lived obstacle layer's eyes: a depth image to marked and cleared cells.

Every `stride`-th pixel with a return nearer than `max_range_m` is back-projected to the
world (`common.camera`: eq. 1 through `T_world_camera = T_world_base · T_base_camera`,
the base where the robot's odometry had it at the frame's stamp).
Points between `min_height_m` and `max_height_m` above the floor the frame shows
(`heights_above_floor`: not the floor, not above the robot)
mark their cells, except cells already in the static map and those under the robot's own
footprint. Clearing: a marked cell whose centre (at two heights) projects into the image
with a measured depth beyond it by `see_through_m` has been seen through, and is
forgotten.

`DepthFeed.update(b, …)` applies the camera's frame stamped b to the layer, at the ticks
that are multiples of the camera's period (ns of sim time): it waits for that frame up to
`timeout_s` wall seconds (a frame that does not come is logged and skipped), clears the
active cells the frame sees through, then marks what it shows. It runs on navigation's
loop thread only.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from common.bus import WaitTimeout
from common.camera import PinholeCamera
from common.geometry import FloatArray
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.sim import CameraFrame
from services.navigation.costmap import ObstacleLayer
from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint


@dataclass(frozen=True)
class DepthParams:
    """What of a depth image marks and clears cells (see the module docstring; m, pixels).
    Not settings: tuned with the head camera and the footprint."""

    stride: int = 4
    min_height_m: float = 0.08
    max_height_m: float = 1.8
    max_range_m: float = 4.0
    see_through_m: float = 0.15
    #: The floor the frame shows: points within this of z = 0 fit it (m), at least so
    #: many of them, and a fit tilted more than `floor_max_tilt_rad` or offset more than
    #: `floor_max_offset_m` is not the floor (z = 0 is kept).
    floor_band_m: float = 0.12
    floor_min_points: int = 200
    floor_max_tilt_rad: float = 0.06
    floor_max_offset_m: float = 0.08


def heights_above_floor(pts: NDArray[np.float64], p: DepthParams) -> NDArray[np.float64]:
    """Each point's (n, 3, world) height above the floor the frame itself shows: a plane
    z = a x + b y + c fitted by least squares to the points near z = 0, twice (the second
    time without those more than 3 cm off the first fit); the world's z where the frame
    shows too little floor or the fit is not a floor. The base's roll and pitch come from
    the robot's own estimate: 1° off puts the floor 7 cm up at 4 m, over `min_height_m`,
    a wall of phantom obstacles; measured from the floor seen, it stays on the floor."""
    z = pts[:, 2]
    near = np.abs(z) < p.floor_band_m
    if int(near.sum()) < p.floor_min_points:
        return z
    xy0 = pts[near, :2].mean(axis=0)
    A = np.column_stack([pts[near, 0] - xy0[0], pts[near, 1] - xy0[1], np.ones(int(near.sum()))])
    zf = z[near]
    coef = np.linalg.lstsq(A, zf, rcond=None)[0]
    inliers = np.abs(A @ coef - zf) < 0.03
    if int(inliers.sum()) >= p.floor_min_points:
        coef = np.linalg.lstsq(A[inliers], zf[inliers], rcond=None)[0]
    a, b, c = (float(v) for v in coef)
    if math.hypot(a, b) > math.tan(p.floor_max_tilt_rad) or abs(c) > p.floor_max_offset_m:
        return z
    return z - (a * (pts[:, 0] - xy0[0]) + b * (pts[:, 1] - xy0[1]) + c)


def obstacle_cells(
    cam: PinholeCamera, grid: Grid, pose: Pose, fp: Footprint, p: DepthParams
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Cells (iy, ix) to mark from one frame (the camera with its depth image)."""
    pts = cam.points_world(stride=p.stride, max_depth_m=p.max_range_m)
    height = heights_above_floor(pts, p)
    keep = (height > p.min_height_m) & (height < p.max_height_m)
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


class Frames(Protocol):
    """A camera's newest frames (`common.bus.Latest`)."""

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CameraFrame: ...
    def at(self, stamp_ns: int) -> CameraFrame | None: ...


class DepthFeed:
    """One depth camera's frames into the short-lived layer; see the module docstring."""

    def __init__(
        self,
        frames: Frames,
        camera: str,
        period_ns: int,
        fp: Footprint,
        log: logging.Logger,
        timeout_s: float,
        p: DepthParams = DepthParams(),
    ) -> None:
        self.frames, self.camera, self.period_ns = frames, camera, period_ns
        self.fp, self.log, self.timeout_s, self.p = fp, log, timeout_s, p

    def update(
        self,
        b: int,
        pose: Pose,
        T_world_base: FloatArray,
        grid: Grid | None,
        layer: ObstacleLayer,
    ) -> bool:
        """Clear and mark `layer` from the frame stamped b, the base at `pose` (and in 3-D
        at `T_world_base`, 4×4: `odom` at b); whether it touched a cell (or held any
        active one)."""
        if grid is None or b % self.period_ns:
            return False
        try:
            self.frames.wait_stamp(b, self.timeout_s)
        except WaitTimeout:
            self.log.warning("no %s frame for t=%.2f s", self.camera, b / NS_PER_S)
            return False
        f = self.frames.at(b)
        if f is None or f.stamp_ns != b:
            return False
        T = T_world_base @ np.array(f.T_base_camera).reshape(4, 4)
        cam = PinholeCamera(
            f.fx, f.fy, f.cx, f.cy, T, np.asarray(as_numpy(f.depth), dtype=np.float32)
        )
        iy, ix = np.nonzero(layer.active(b))
        through = seen_through(cam, grid, iy, ix, self.p)
        layer.clear(iy[through], ix[through])
        my, mx = obstacle_cells(cam, grid, pose, self.fp, self.p)
        layer.mark(my, mx, b)
        return bool(len(my) or through.any() or len(iy))
