"""Global planning on the costmap: goal checks, A*, smoothing, headings.

`plan(costmap, start, goal, fp, settings)` (`navigation.planner`):
1. the goal: its footprint (grown by `GOAL_MARGIN_M`) must be free and its cell not
   lethal; if not, the nearest pose within `goal_search_m` that is (same yaw) replaces
   it, else `PlanError("invalid_goal")`;
2. the start: a robot standing in the inflated zone (pushed, or a goal near a wall) may
   leave it: lethal inflation around the start becomes expensive instead of forbidden;
3. A* over the cost grid (`native.search`: 8-connected, edge = length · (1 + w · cost));
   no path → `PlanError("no_path")`;
4. smoothing: greedy string pulling — a shortcut replaces a stretch of the path when the
   straight segment crosses no lethal cell and no cell costlier than the stretch's own
   worst, so smoothing never takes the robot closer to obstacles or people;
5. poses every `SPACING_M` along the polyline, yaw along the path, the goal's at the end.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from common.config import PlannerSettings
from common.messages.navigation import NavFailure
from services.navigation import native
from services.navigation.costmap import LETHAL, Costmap
from services.navigation.grid import Footprint, Pose, footprint_free

#: Not settings (those are `PlannerSettings`, `navigation.planner`): the clearance kept
#: around the footprint at the goal (m), the spacing of the poses (m), and what a lethal
#: inflated cell around the start costs instead (`_escape_start`).
GOAL_MARGIN_M = 0.03
SPACING_M = 0.05
START_ESCAPE_COST = 3.0


class Plan(NamedTuple):
    """poses: (n, 3) x, y, yaw (world). goal: the pose planned to (may have moved).
    length_m: along the poses. cost: A*'s cost in cells. expanded: A*'s closed nodes."""

    poses: NDArray[np.float64]
    goal: Pose
    length_m: float
    cost: float
    expanded: int


class PlanError(Exception):
    """Planning failed: `reason` a typed `NavFailure`, the message a sentence."""

    def __init__(self, reason: NavFailure, message: str) -> None:
        self.reason: NavFailure = reason
        super().__init__(message)


def pose_ok(costmap: Costmap, pose: Pose, fp: Footprint, margin: float) -> bool:
    """A pose the robot may stop at: cell not lethal, footprint on free cells."""
    cell = costmap.grid.cell(pose.x, pose.y)
    if cell is None or costmap.cost[cell] < 0:
        return False
    return footprint_free(costmap.occupied, costmap.grid, pose, fp, margin)


def nearest_free_pose(
    costmap: Costmap, pose: Pose, fp: Footprint, search_m: float, margin: float
) -> Pose | None:
    """The pose closest to `pose` (same yaw, within `search_m`) that `pose_ok` accepts."""
    if pose_ok(costmap, pose, fp, margin):
        return pose
    grid = costmap.grid
    r = math.ceil(search_m / grid.resolution)
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    d = np.hypot(dx, dy) * grid.resolution
    keep = d <= search_m
    order = np.argsort(d[keep], kind="stable")
    for oy, ox in zip(dy[keep][order], dx[keep][order], strict=True):
        cand = Pose(pose.x + ox * grid.resolution, pose.y + oy * grid.resolution, pose.yaw)
        if pose_ok(costmap, cand, fp, margin):
            return cand
    return None


def _escape_start(
    cost: NDArray[np.float32], costmap: Costmap, cell: tuple[int, int], fp: Footprint
) -> NDArray[np.float32]:
    """Lethal inflation near the start becomes costly but passable (real obstacles stay)."""
    out = cost.copy()
    r = math.ceil((fp.half_width + 0.2) / costmap.grid.resolution)
    iy0, ix0 = max(0, cell[0] - r), max(0, cell[1] - r)
    window = out[iy0 : cell[0] + r + 1, ix0 : cell[1] + r + 1]
    occ = costmap.occupied[iy0 : cell[0] + r + 1, ix0 : cell[1] + r + 1]
    window[(window < 0) & ~occ] = START_ESCAPE_COST
    return out


#: A failed plan names the people within this of the start, m: their lethal discs may be
#: what encloses the robot.
PEOPLE_NEAR_M = 2.5


def _people_near(costmap: Costmap, start: Pose) -> str:
    near = sorted(
        (math.hypot(q.x - start.x, q.y - start.y), q.id)
        for q in costmap.people
        if math.hypot(q.x - start.x, q.y - start.y) <= PEOPLE_NEAR_M
    )
    return "; people near: " + ", ".join(f"{i} at {d:.2f} m" for d, i in near) if near else ""


def plan(costmap: Costmap, start: Pose, goal: Pose, fp: Footprint, p: PlannerSettings) -> Plan:
    """The path from start to goal, or `PlanError` (see the module docstring)."""
    grid = costmap.grid
    target = nearest_free_pose(costmap, goal, fp, p.goal_search_m, GOAL_MARGIN_M)
    if target is None:
        raise PlanError(
            "invalid_goal",
            f"goal ({goal.x:.2f}, {goal.y:.2f}, {goal.yaw:.2f}) is in an obstacle and no free "
            f"pose lies within {p.goal_search_m:.2f} m",
        )
    s_cell, g_cell = grid.cell(start.x, start.y), grid.cell(target.x, target.y)
    if s_cell is None:
        raise PlanError("no_path", f"start ({start.x:.2f}, {start.y:.2f}) is off the map")
    assert g_cell is not None  # pose_ok checked it
    cost = costmap.cost
    if cost[s_cell] < 0:
        cost = _escape_start(cost, costmap, s_cell, fp)
        if cost[s_cell] < 0:
            raise PlanError("no_path", f"start ({start.x:.2f}, {start.y:.2f}) is in an obstacle")
    found = native.search(cost, s_cell, g_cell, p.cost_weight)
    if not len(found.cells):
        raise PlanError(
            "no_path",
            f"no path from ({start.x:.2f}, {start.y:.2f}) to ({target.x:.2f}, {target.y:.2f}) "
            f"({found.expanded} cells searched{_people_near(costmap, start)})",
        )
    keep = smooth(cost, found.cells)
    xy = grid.centres(found.cells[keep])
    xy[0] = (start.x, start.y)
    xy[-1] = (target.x, target.y)
    poses = resample(xy, SPACING_M, target.yaw)
    length = float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T))) if len(poses) > 1 else 0.0
    return Plan(poses, target, length, found.cost, found.expanded)


def path_cost(costmap: Costmap, poses: NDArray[np.float64], weight: float) -> float:
    """What a path costs on `costmap`, in A*'s measure but metres: each step's length ·
    (1 + weight · cost of the cell it ends in); a step into a lethal cell or off the grid
    costs infinity. The first pose (where the robot stands) is not charged: a robot
    pushed into the inflation has every way out through it."""
    if len(poses) < 2:
        return 0.0
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    iy, ix, inside = costmap.grid.cells(poses[1:, :2])
    cost = costmap.cost[iy, ix]
    if not np.all(inside) or np.any(cost < 0):
        return math.inf
    return float(np.sum(steps * (1.0 + weight * cost)))


def _segment_cells(
    a: NDArray[np.int64], b: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    n = int(np.max(np.abs(b - a))) * 2 + 1
    t = np.linspace(0.0, 1.0, n)
    iy = np.rint(a[0] + t * (b[0] - a[0])).astype(np.int64)
    ix = np.rint(a[1] + t * (b[1] - a[1])).astype(np.int64)
    return iy, ix


def smooth(cost: NDArray[np.float32], cells: NDArray[np.int64]) -> NDArray[np.int64]:
    """Indices into `cells` of the string-pulled path (first and last kept).

    Only the corners of the 8-connected path (where its step changes) are candidates: a
    straight run between them adds nothing, and it keeps the checks few.
    """
    n = len(cells)
    if n <= 2:
        return np.arange(n)
    steps = np.diff(cells, axis=0)
    turns = np.nonzero(np.any(steps[1:] != steps[:-1], axis=1))[0] + 1
    corners = np.concatenate([[0], turns, [n - 1]])
    along = cost[cells[:, 0], cells[:, 1]]
    keep = [0]
    a = 0  # index into corners
    while a < len(corners) - 1:
        best = a + 1
        for b in range(a + 2, len(corners)):
            i, j = corners[a], corners[b]
            iy, ix = _segment_cells(cells[i], cells[j])
            seg = cost[iy, ix]
            if np.any(seg < 0) or float(seg.max()) > float(along[i : j + 1].max()) + 1e-6:
                if b - best > 6:  # well past the last good shortcut: stop looking
                    break
            else:
                best = b
        keep.append(int(corners[best]))
        a = best
    return np.array(keep)


def resample(xy: NDArray[np.float64], spacing: float, goal_yaw: float) -> NDArray[np.float64]:
    """Poses (m, 3) every `spacing` along the polyline, yaw along it, goal_yaw at the end."""
    seg = np.diff(xy, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    keep = np.concatenate([[True], lengths > 1e-9])
    xy, lengths = xy[keep], lengths[lengths > 1e-9]
    if len(xy) == 1:
        return np.array([[xy[0, 0], xy[0, 1], goal_yaw]])
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    ts = np.append(np.arange(0.0, s[-1], spacing), s[-1])
    x = np.interp(ts, s, xy[:, 0])
    y = np.interp(ts, s, xy[:, 1])
    seg_idx = np.clip(np.searchsorted(s, ts, side="right") - 1, 0, len(lengths) - 1)
    d = np.diff(xy, axis=0)
    yaw = np.arctan2(d[seg_idx, 1], d[seg_idx, 0])
    yaw[-1] = goal_yaw
    return np.stack([x, y, yaw], axis=1)


__all__ = ["GOAL_MARGIN_M", "LETHAL", "Plan", "PlanError", "nearest_free_pose", "path_cost", "plan",
           "pose_ok"]  # fmt: skip
