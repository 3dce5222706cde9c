"""Floor geometry of a world: occupancy rasterization, robot poses, reachability.

Pure numpy/scipy on the 2-D floor; no MuJoCo. The robot is a rectangle (its footprint,
`common.robot.FOOTPRINT_BOUNDS`, arm stowed) about the base origin. A goal pose is feasible
when that rectangle, grown by a margin, overlaps no occupied cell, and reachable when its
cell lies in the start's connected component of the free space shrunk by the footprint's
half width (the robot walks along its path, so its width is what must fit through an
aisle). Distances come from one `scipy.ndimage.distance_transform_edt`, components from one
`scipy.ndimage.label`.

Goal poses for an artifact face it along the outward normal of its surface's nearest edge:
the standoff pose (navigation's goal, `STANDOFF_DISTANCE_M` away, where the wrist camera
looks in the `look` posture) and the pick pose (`D_OPT_M`, where visual servoing ends). The
robot walks straight from one to the other, so both rectangles free means the sweep is.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from common import robot
from common.messages.arrays import as_numpy, to_wire
from common.messages.world import (
    FREE,
    OCCUPIED,
    Artifact,
    Hall,
    Obstacle,
    OccupancyGrid,
    SupportSurface,
    WorldDescription,
)
from common.robot import Footprint

#: Cell side of the occupancy grid, m.
RESOLUTION_M = 0.05
#: Extra clearance around the footprint at a goal pose, m (on top of the cells' own overlap).
GOAL_MARGIN_M = 0.02
#: Extra clearance beyond the footprint's half width along a path, m.
PATH_MARGIN_M = 0.05


class Pose2D(NamedTuple):
    """A pose on the floor: x, y in m (world) and yaw in rad."""

    x: float
    y: float
    yaw: float


def robot_footprint() -> Footprint:
    """The footprint from `common.robot.FOOTPRINT_BOUNDS` (x_min, x_max, y_min, y_max)."""
    return Footprint.stowed()


def box_corners(
    centre_xy: tuple[float, float], half_xy: tuple[float, float], yaw: float
) -> NDArray[np.float64]:
    """The four floor corners (4, 2) of a rectangle, counter-clockwise."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * half_xy
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.asarray(centre_xy, dtype=float)


def cell_centres(grid: OccupancyGrid) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World x (nx,) and y (ny,) of the cell centres."""
    ny, nx = grid.cells.shape
    xs = grid.origin[0] + (np.arange(nx, dtype=np.float64) + 0.5) * grid.resolution
    ys = grid.origin[1] + (np.arange(ny, dtype=np.float64) + 0.5) * grid.resolution
    return xs, ys


def cell_of(grid: OccupancyGrid, x: float, y: float) -> tuple[int, int] | None:
    """The (iy, ix) of the cell containing (x, y), or None outside the grid."""
    ny, nx = grid.cells.shape
    ix = math.floor((x - grid.origin[0]) / grid.resolution)
    iy = math.floor((y - grid.origin[1]) / grid.resolution)
    if 0 <= ix < nx and 0 <= iy < ny:
        return iy, ix
    return None


def rect_mask(
    xs: NDArray[np.float64],
    ys: NDArray[np.float64],
    centre_xy: tuple[float, float],
    yaw: float,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
) -> NDArray[np.bool_]:
    """Cells (ny, nx) whose centres lie in a rectangle given in its own frame."""
    c, s = math.cos(yaw), math.sin(yaw)
    dx = xs[None, :] - centre_xy[0]
    dy = ys[:, None] - centre_xy[1]
    u = c * dx + s * dy
    v = -s * dx + c * dy
    return (u >= x_range[0]) & (u <= x_range[1]) & (v >= y_range[0]) & (v <= y_range[1])


def rasterize(
    hall: Hall, obstacles: tuple[Obstacle, ...], resolution: float = RESOLUTION_M
) -> OccupancyGrid:
    """The occupancy grid of the hall and its walls: a cell is occupied when it overlaps a box.

    Overlap is tested on cell centres against each box grown by half a cell, which is exact
    for axis-aligned boxes and errs on the occupied side at a rotated box's corners.
    """
    wall = 0.5  # margin beyond the interior, enough for the perimeter walls
    x0, y0 = hall.min_xy[0] - wall, hall.min_xy[1] - wall
    nx = math.ceil((hall.max_xy[0] + wall - x0) / resolution)
    ny = math.ceil((hall.max_xy[1] + wall - y0) / resolution)
    xs = x0 + (np.arange(nx, dtype=np.float64) + 0.5) * resolution
    ys = y0 + (np.arange(ny, dtype=np.float64) + 0.5) * resolution
    cells = np.full((ny, nx), FREE, dtype=np.uint8)
    grow = 0.5 * resolution
    for ob in obstacles:
        hx, hy = ob.half_size[0] + grow, ob.half_size[1] + grow
        mask = rect_mask(xs, ys, ob.centre[:2], ob.yaw, (-hx, hx), (-hy, hy))
        cells[mask] = OCCUPIED
    return OccupancyGrid(resolution=resolution, origin=(x0, y0), cells=to_wire(cells))


def clearance(grid: OccupancyGrid) -> NDArray[np.float64]:
    """Distance (ny, nx) in m from each cell centre to the nearest occupied cell centre.

    The outside of the grid counts as occupied, so door openings do not lead anywhere.
    """
    free = as_numpy(grid.cells) == FREE
    padded = np.pad(free, 1, constant_values=False)
    return ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * grid.resolution


def footprint_free(
    grid: OccupancyGrid, pose: Pose2D, footprint: Footprint, margin: float = GOAL_MARGIN_M
) -> bool:
    """Whether the footprint at `pose`, grown by `margin`, overlaps only free cells.

    A cell overlaps when its centre lies within the rectangle grown by half a cell. The
    footprint must lie inside the grid.
    """
    grow = margin + 0.5 * grid.resolution
    x_range = (-footprint.back - grow, footprint.front + grow)
    y_range = (-footprint.half_width - grow, footprint.half_width + grow)
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    corners = [(pose.x + c * u - s * v, pose.y + s * u + c * v) for u in x_range for v in y_range]
    cells = [cell_of(grid, x, y) for x, y in corners]
    if any(cell is None for cell in cells):
        return False
    iy = [cell[0] for cell in cells if cell is not None]
    ix = [cell[1] for cell in cells if cell is not None]
    window = as_numpy(grid.cells)[min(iy) : max(iy) + 1, min(ix) : max(ix) + 1]
    xs, ys = cell_centres(grid)
    xs, ys = xs[min(ix) : max(ix) + 1], ys[min(iy) : max(iy) + 1]
    mask = rect_mask(xs, ys, (pose.x, pose.y), pose.yaw, x_range, y_range)
    return not bool(np.any(window[mask] != FREE))


def reachable_components(grid: OccupancyGrid, radius: float) -> NDArray[np.int32]:
    """Labels (ny, nx) of the 4-connected regions whose clearance exceeds `radius`; 0 elsewhere."""
    passable = clearance(grid) > radius
    labels, _ = ndimage.label(passable)
    return labels.astype(np.int32)


def surface_normal_towards(
    surface: SupportSurface, xy: tuple[float, float]
) -> tuple[NDArray[np.float64], float]:
    """The outward unit normal (2,) of the surface edge nearest to `xy`, and xy's depth from it.

    Depth is the distance from that edge inward (positive when xy is on the surface).
    """
    c, s = math.cos(surface.yaw), math.sin(surface.yaw)
    dx, dy = xy[0] - surface.centre_xy[0], xy[1] - surface.centre_xy[1]
    u, v = c * dx + s * dy, -s * dx + c * dy
    hx, hy = surface.half_extents
    depths = {(1.0, 0.0): hx - u, (-1.0, 0.0): hx + u, (0.0, 1.0): hy - v, (0.0, -1.0): hy + v}
    (nu, nv), depth = min(depths.items(), key=lambda item: item[1])
    normal = np.array([c * nu - s * nv, s * nu + c * nv])
    return normal, depth


def standoff_pose_for(
    artifact: Artifact,
    surface: SupportSurface,
    distance: float,
    heading: float = 0.0,
) -> Pose2D:
    """The base pose on the outward normal of the artifact's nearest edge, `distance` away.

    The base origin is at horizontal `distance` from the artifact's axis and sees it at
    bearing `heading` (rad, in `base_yaw`; 0 = straight ahead).
    """
    normal, _ = surface_normal_towards(surface, artifact.position[:2])
    x = artifact.position[0] + distance * normal[0]
    y = artifact.position[1] + distance * normal[1]
    yaw = math.atan2(-normal[1], -normal[0]) - heading
    return Pose2D(float(x), float(y), math.remainder(yaw, math.tau))


def _artifact_pose(world: WorldDescription, artifact_id: str, distance: float) -> Pose2D:
    artifacts = {a.id: a for a in world.artifacts}
    if artifact_id not in artifacts:
        raise KeyError(f"no artifact {artifact_id!r}; the world has {sorted(artifacts)}")
    artifact = artifacts[artifact_id]
    surface = next(s for s in world.surfaces if s.id == artifact.surface_id)
    return standoff_pose_for(artifact, surface, distance, robot.THETA_OPT_RAD)


def standoff_pose(world: WorldDescription, artifact_id: str) -> Pose2D:
    """Navigation's goal (x, y, yaw) facing an artifact, `STANDOFF_DISTANCE_M` from it."""
    return _artifact_pose(world, artifact_id, robot.STANDOFF_DISTANCE_M)


def pick_pose(world: WorldDescription, artifact_id: str) -> Pose2D:
    """Where the approach ends (x, y, yaw): facing the artifact, `D_OPT_M` from it."""
    return _artifact_pose(world, artifact_id, robot.D_OPT_M)


def handover_pose_for(position: tuple[float, float], yaw: float, distance: float) -> Pose2D:
    """The base pose facing a person at `position` who faces `yaw`, `distance` in front."""
    x = position[0] + distance * math.cos(yaw)
    y = position[1] + distance * math.sin(yaw)
    return Pose2D(x, y, math.remainder(yaw + math.pi, math.tau))


def handover_distance() -> float:
    """Base-to-person distance at a handover, m (`common.robot.HANDOVER_DISTANCE_M`)."""
    return float(robot.HANDOVER_DISTANCE_M)


def handover_pose(world: WorldDescription, person_id: str) -> Pose2D:
    """The handover pose (x, y, yaw) in front of a person, facing them."""
    people = {p.id: p for p in world.people}
    if person_id not in people:
        raise KeyError(f"no person {person_id!r}; the world has {sorted(people)}")
    person = people[person_id]
    return handover_pose_for(person.position, person.yaw, handover_distance())


def check_paths(world: WorldDescription) -> list[str]:
    """Problems with the world's goal poses and paths; empty when every goal is reachable.

    Checked: the start, every artifact's standoff and pick poses and every person's
    handover pose have a free footprint, and each lies in the start's component of the
    free space shrunk by the footprint's half width.
    """
    footprint = robot_footprint()
    grid = world.occupancy
    labels = reachable_components(grid, footprint.half_width + PATH_MARGIN_M)
    start = Pose2D(world.robot_start.x, world.robot_start.y, world.robot_start.yaw)
    goals = [("robot start", start)]
    goals += [(f"standoff of {a.id}", standoff_pose(world, a.id)) for a in world.artifacts]
    goals += [(f"pick pose of {a.id}", pick_pose(world, a.id)) for a in world.artifacts]
    goals += [(f"handover to {p.id}", handover_pose(world, p.id)) for p in world.people]
    problems: list[str] = []
    start_cell = cell_of(grid, start.x, start.y)
    start_label = int(labels[start_cell]) if start_cell is not None else 0
    if start_label == 0:
        problems.append(f"robot start ({start.x:.2f}, {start.y:.2f}) is not in free space")
    for what, pose in goals:
        if not footprint_free(grid, pose, footprint):
            problems.append(
                f"{what} ({pose.x:.2f}, {pose.y:.2f}, {pose.yaw:.2f}) footprint hits obstacles"
            )
            continue
        cell = cell_of(grid, pose.x, pose.y)
        if start_label and (cell is None or int(labels[cell]) != start_label):
            problems.append(f"{what} ({pose.x:.2f}, {pose.y:.2f}) is not reachable from start")
    return problems
