"""The floor grid and the robot's footprint on it: cells, world coordinates, collisions.

A `Grid` is a boolean occupancy (`occupied[iy, ix]`) with its resolution and the world
position of cell (0, 0)'s outer corner; cell (iy, ix) has its centre at
origin + ((ix + 0.5) res, (iy + 0.5) res). It is built from the semantic map's
`OccupancyGrid` (unknown counts as occupied: the robot never walks where nobody looked)
or from the sim's truth grid (`navigation.map_source = "world"`). The footprint is the
robot's floor rectangle with the arm stowed (`common.robot.FOOTPRINT_BOUNDS`) about the
base origin; `footprint_free` samples it at half-cell spacing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from common.map_frame import odom_pose
from common.messages import semantic_map, world
from common.messages.arrays import as_numpy
from common.messages.sim import Odom, StateTruth
from common.robot import Footprint

BoolGrid = NDArray[np.bool_]
FloatGrid = NDArray[np.float64]


class Pose(NamedTuple):
    """A pose on the floor: x, y in m (world) and yaw in rad."""

    x: float
    y: float
    yaw: float

    @classmethod
    def of_odom(cls, odom: Odom | StateTruth) -> Pose:
        """The base's pose on the floor from its odometry (or the sim's truth)."""
        return cls(*odom_pose(odom))


@dataclass(frozen=True)
class Grid:
    """Occupancy (ny, nx) bool, cell side `resolution` m, `origin` the corner of cell (0, 0)."""

    occupied: BoolGrid
    resolution: float
    origin: tuple[float, float]
    #: The cells known to hold something (unknown ones left out); None: `occupied`.
    solid: BoolGrid | None = None

    @property
    def known_occupied(self) -> BoolGrid:
        return self.occupied if self.solid is None else self.solid

    @property
    def shape(self) -> tuple[int, int]:
        ny, nx = self.occupied.shape
        return int(ny), int(nx)

    @classmethod
    def from_world(cls, grid: world.OccupancyGrid) -> Grid:
        cells = np.asarray(as_numpy(grid.cells))
        return cls(
            cells != world.FREE,
            float(grid.resolution),
            tuple(grid.origin),  # type: ignore[arg-type]
            cells == world.OCCUPIED,
        )

    @classmethod
    def from_map(cls, grid: semantic_map.OccupancyGrid) -> Grid:
        cells = np.asarray(as_numpy(grid.cells))
        if cells.ndim != 2 or grid.resolution_m <= 0:
            raise ValueError(f"occupancy grid of shape {cells.shape}, res {grid.resolution_m}")
        return cls(
            cells != world.FREE,  # the map uses the world's codes (unknown 255)
            float(grid.resolution_m),
            grid.origin_xy,
            cells == world.OCCUPIED,
        )

    def cell(self, x: float, y: float) -> tuple[int, int] | None:
        """The (iy, ix) holding (x, y), or None outside the grid."""
        ix = math.floor((x - self.origin[0]) / self.resolution)
        iy = math.floor((y - self.origin[1]) / self.resolution)
        ny, nx = self.shape
        return (iy, ix) if 0 <= ix < nx and 0 <= iy < ny else None

    def cells(
        self, xy: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], BoolGrid]:
        """Cell indices (iy, ix) of points (n, 2), clipped, and which points lie inside."""
        ix = np.floor((xy[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((xy[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        ny, nx = self.shape
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return np.clip(iy, 0, ny - 1), np.clip(ix, 0, nx - 1), inside

    def centre(self, iy: int, ix: int) -> tuple[float, float]:
        return (
            self.origin[0] + (ix + 0.5) * self.resolution,
            self.origin[1] + (iy + 0.5) * self.resolution,
        )

    def centres(self, cells: NDArray[np.int64]) -> NDArray[np.float64]:
        """World xy (n, 2) of cells (n, 2) given as (iy, ix)."""
        out = np.empty((len(cells), 2))
        out[:, 0] = self.origin[0] + (cells[:, 1] + 0.5) * self.resolution
        out[:, 1] = self.origin[1] + (cells[:, 0] + 0.5) * self.resolution
        return out


def footprint_points(fp: Footprint, margin: float, spacing: float) -> NDArray[np.float64]:
    """Points (n, 2) covering the footprint grown by `margin`, in the base frame."""
    us = np.linspace(
        -fp.back - margin,
        fp.front + margin,
        2 + math.ceil((fp.front + fp.back + 2 * margin) / spacing),
    )
    vs = np.linspace(
        -fp.half_width - margin,
        fp.half_width + margin,
        2 + math.ceil((2 * fp.half_width + 2 * margin) / spacing),
    )
    u, v = np.meshgrid(us, vs)
    return np.stack([u.ravel(), v.ravel()], axis=1)


def footprint_free(
    occupied: BoolGrid, grid: Grid, pose: Pose, fp: Footprint, margin: float
) -> bool:
    """Whether the footprint at `pose`, grown by `margin`, lies on free cells inside the grid."""
    local = footprint_points(fp, margin, 0.5 * grid.resolution)
    return not footprint_hits(occupied, grid, pose, local).any()


def footprint_hits(
    occupied: BoolGrid,
    grid: Grid,
    pose: Pose,
    local: NDArray[np.float64],
    off_grid: bool = True,
) -> NDArray[np.bool_]:
    """Per point of `local` (n, 2, the base frame: `footprint_points`) placed at `pose`:
    whether it lies on an occupied cell, or off the grid (when `off_grid`)."""
    at = np.array([[pose.x, pose.y, pose.yaw]])
    return footprints_hits(occupied, grid, at, local, off_grid)[0]


def footprints_hits(
    occupied: BoolGrid,
    grid: Grid,
    poses: NDArray[np.float64],
    local: NDArray[np.float64],
    off_grid: bool = True,
) -> NDArray[np.bool_]:
    """`footprint_hits` at many poses (k, 3: x, y, yaw) in one lookup: (k, n), per pose
    and point of `local` (a whole turn's sweep at once)."""
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    u, v = local[None, :, 0], local[None, :, 1]
    xy = np.empty((len(poses), len(local), 2))
    xy[..., 0] = poses[:, 0:1] + c * u - s * v
    xy[..., 1] = poses[:, 1:2] + s * u + c * v
    iy, ix, inside = grid.cells(xy.reshape(-1, 2))
    hits: NDArray[np.bool_] = occupied[iy, ix] & inside
    if off_grid:
        hits |= ~inside
    return hits.reshape(len(poses), -1)


def distance_to_footprint(
    pose: Pose, fp: Footprint, points: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance (n,) in m from the footprint rectangle at `pose` to points (n, 2) (0 inside)."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = points[:, 0] - pose.x, points[:, 1] - pose.y
    u, v = c * dx + s * dy, -s * dx + c * dy
    du = np.maximum(np.maximum(u - fp.front, -fp.back - u), 0.0)
    dv = np.maximum(np.abs(v) - fp.half_width, 0.0)
    return np.hypot(du, dv)
