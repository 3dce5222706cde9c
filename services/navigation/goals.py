"""Goal poses from the map's data: an artifact's standoff pose and a person's handover pose.

Standoff (the paper's "obstacle-free region in front of the object"): the artifact stands
near the edge of a table or bench, which the occupancy grid holds. Casting rays from the
artifact every `ray_step_rad`, the ray that leaves the occupied cells soonest crosses the
nearest edge; the rays within `NORMAL_BAND_M` of the shortest are symmetric about the
edge's outward normal, so their mean direction is that normal — the direction the world
generator uses (`services.sim.feasibility.standoff_pose_for`, computed there from the
surface's rectangle). The pose lies `STANDOFF_DISTANCE_M` out along it, facing the
artifact; when its footprint is not free, directions further from the normal are tried
in turn, so a crowded edge still gives a free pose. A goal may ask for the sides to
stand on instead (`ArtifactStandoff.bearings_rad`: a box held along its long faces).

Handover: `HANDOVER_DISTANCE_M` from the person's latest position, facing them; on the
side the goal asks for (`PersonHandover.bearing_rad`), else in front of them when their
heading is known, else on the robot's side; when that footprint is not free, the nearest
free direction (by angle) around them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common import robot
from common.messages.navigation import NavGoalRequest
from services.navigation.costmap import Costmap, Person
from services.navigation.grid import Footprint, Pose, footprint_hits, footprint_points
from services.navigation.planner import GOAL_MARGIN_M, pose_ok

RAY_STEP_RAD = math.radians(1.0)
#: Rays leaving within this much of the shortest exit are averaged into the normal, m.
NORMAL_BAND_M = 0.02
MAX_RAY_M = 1.5
#: A ray is out when it stays on free cells this far (the robot's half-width and more), m.
EXIT_RUN_M = 0.3


class GoalError(ValueError):
    """No free goal pose: what was tried."""


class GoalInvalid(ValueError):
    """A goal that cannot be resolved (unknown id, no free pose, off the map): why."""


@dataclass(frozen=True)
class Queued:
    """A goal taken before navigation had a map: resolved when the map is in."""

    goal_id: str
    request: NavGoalRequest
    #: The first tick it waited at (ns; −1 before it).
    since_ns: int = -1


def exit_distances(costmap: Costmap, x: float, y: float, angles: np.ndarray) -> np.ndarray:
    """Per direction, the distance (m) from (x, y) to where the ray comes out into open
    floor: the first free cell from which it stays free for `EXIT_RUN_M` (`MAX_RAY_M`
    when none within it). A strip of free cells that ends in unknown or occupied cells
    is no way out: an explored bench's lidar band has one behind it (beams under the top)
    and its "exit" 1 cm behind the can turned the standoff round the bench's end (hall
    seed 0), where the hip met the bench 5 cm short of the grasp distance."""
    grid = costmap.grid
    step = 0.2 * grid.resolution
    steps = np.arange(0.0, MAX_RAY_M + EXIT_RUN_M, step)
    px = x + np.cos(angles)[:, None] * steps[None, :]
    py = y + np.sin(angles)[:, None] * steps[None, :]
    iy, ix, inside = grid.cells(np.stack([px.ravel(), py.ravel()], axis=1))
    free = ~(grid.occupied[iy, ix] & inside).reshape(px.shape)
    run = np.zeros_like(free, dtype=np.int64)  # free steps from each one on, itself included
    ahead = np.zeros(len(angles), dtype=np.int64)
    for j in range(len(steps) - 1, -1, -1):
        ahead = (ahead + 1) * free[:, j]
        run[:, j] = ahead
    opens = run >= round(EXIT_RUN_M / step)
    opens[:, steps >= MAX_RAY_M] = False
    first = np.where(opens.any(axis=1), opens.argmax(axis=1), 0)
    out: np.ndarray = np.where(opens.any(axis=1), steps[first], MAX_RAY_M)
    return out


def standoff_pose(
    costmap: Costmap,
    x: float,
    y: float,
    fp: Footprint,
    margin: float = GOAL_MARGIN_M,
    bearings: tuple[float, ...] = (),
    tolerance: float = math.pi,
) -> Pose:
    """A free pose facing the artifact at (x, y), `STANDOFF_DISTANCE_M` away: off the
    nearest edge (the directions nearest its normal first) or, given `bearings` (world
    bearings from the artifact), the direction nearest any of them, within `tolerance`."""
    angles = np.arange(0.0, 2 * math.pi, RAY_STEP_RAD)
    if bearings:
        off = np.abs(np.angle(np.exp(1j * (angles[:, None] - np.asarray(bearings)[None, :]))))
        away = off.min(axis=1)
        order = np.argsort(away, kind="stable")
        order = order[away[order] <= tolerance + 1e-9]
    else:
        exits = exit_distances(costmap, x, y, angles)
        near = exits <= exits.min() + NORMAL_BAND_M
        best = float(np.angle(np.exp(1j * angles[near]).sum()))
        order = np.argsort(np.abs(np.angle(np.exp(1j * (angles - best)))), kind="stable")
    d = robot.STANDOFF_DISTANCE_M
    for k in order:
        a = float(angles[k])
        pose = Pose(x + d * math.cos(a), y + d * math.sin(a), math.remainder(a + math.pi, math.tau))
        if pose_ok(costmap, pose, fp, margin):
            return pose
    if not bearings:
        raise GoalError(f"no free standoff pose {d:.2f} m from ({x:.2f}, {y:.2f}) in any direction")
    wanted = ", ".join(f"{math.degrees(b):.0f}°" for b in bearings)
    b = bearings[0]
    nearest = Pose(x + d * math.cos(b), y + d * math.sin(b), b + math.pi)
    raise GoalError(
        f"no free standoff pose {d:.2f} m from ({x:.2f}, {y:.2f}) within "
        f"{math.degrees(tolerance):.0f}° of {wanted}: at {math.degrees(b):.0f}°, "
        f"{blocked_by(costmap, nearest, fp, margin)}"
    )


def blocked_by(costmap: Costmap, pose: Pose, fp: Footprint, margin: float) -> str:
    """Why `pose_ok` refuses `pose`, for a person: off the map, a lethal cell, or where
    its footprint meets occupied cells (their centroid) and which layer holds them."""
    cell = costmap.grid.cell(pose.x, pose.y)
    if cell is None:
        return f"({pose.x:.2f}, {pose.y:.2f}) is off the map"
    local = footprint_points(fp, margin, 0.5 * costmap.grid.resolution)
    hits = footprint_hits(costmap.occupied, costmap.grid, pose, local)
    if not hits.any():
        return f"({pose.x:.2f}, {pose.y:.2f}) lies on a lethal cell (too near an obstacle)"
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    pts = local[hits]
    xy = np.column_stack([pose.x + c * pts[:, 0] - s * pts[:, 1],
                          pose.y + s * pts[:, 0] + c * pts[:, 1]])  # fmt: skip
    iy, ix, _ = costmap.grid.cells(xy)
    static = costmap.grid.occupied[iy, ix]
    what = "the map's obstacles" if static.all() else "the short-lived layers or people"
    mx, my = xy.mean(axis=0)
    return (
        f"the footprint at ({pose.x:.2f}, {pose.y:.2f}) meets {len(pts)} occupied cells "
        f"about ({mx:.2f}, {my:.2f}): {what}"
    )


def handover_pose(
    costmap: Costmap,
    person: Person,
    robot_xy: tuple[float, float],
    fp: Footprint,
    margin: float = GOAL_MARGIN_M,
    bearing: float | None = None,
    distance: float | None = None,
) -> Pose:
    """A free pose facing the person at `distance` (None: `HANDOVER_DISTANCE_M`; see the
    module docstring); `bearing`: the side asked for (the bearing from the person), first."""
    if bearing is not None:
        preferred = bearing
    elif person.yaw is not None:
        preferred = person.yaw
    else:
        preferred = math.atan2(robot_xy[1] - person.y, robot_xy[0] - person.x)
    d = robot.HANDOVER_DISTANCE_M if distance is None else distance
    # The planner's own test (`pose_ok`), so a pose chosen here is one it plans to: the
    # footprint on free cells, the base not in lethal cost (the person's lethal disc ends
    # short of the handover distance).
    for k in range(0, 181, 5):
        for sign in (1, -1) if k else (1,):
            a = preferred + sign * math.radians(k)
            pose = Pose(
                person.x + d * math.cos(a),
                person.y + d * math.sin(a),
                math.remainder(a + math.pi, math.tau),
            )
            if pose_ok(costmap, pose, fp, margin):
                return pose
    raise GoalError(
        f"no free handover pose {d:.2f} m from {person.id} at ({person.x:.2f}, {person.y:.2f})"
    )
