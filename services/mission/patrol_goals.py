"""The mapping patrol's goals: a coverage route as a sequence of navigation pose goals.

`patrol_goals(route, start_yaw, turns)` turns a `Route` into navigation pose goals: for
each viewpoint, a walk there (facing along the last stretch of the route's path to it,
or, on a route with facings, the way its viewpoint faces: a surface pass looks at what
it came for and does not turn round), then `turns` turns on the spot of 360°/turns
each, so the head camera sweeps the whole circle (a turn is a pose goal at the same
place with the next yaw: navigation turns in place). `NavPatrol` steps through them on
the answers it is given: a goal sent, refused, or finished (succeeded or not). A walk
goal that is refused or fails skips its viewpoint (its look-around too) and is counted;
a failed turn is passed over. No transport and no clock here: the patrol
(`services.mission.patrol`) sends the goals and feeds the answers back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from common.geometry import wrap_angle
from services.mission.coverage import Route


@dataclass(frozen=True)
class PatrolGoal:
    """One pose goal of the patrol: its viewpoint (index into the route), the pose in the
    world (m, rad) and whether it is a turn on the spot (`look`) or a walk."""

    viewpoint: int
    x: float
    y: float
    yaw: float
    look: bool


def _arrival_yaw(path: np.ndarray, previous: float) -> float:
    """The heading along the last 0.5 m of a path (`previous` when it is shorter)."""
    end = path[-1]
    for p in path[::-1]:
        if float(np.hypot(*(end - p))) >= 0.5:
            return math.atan2(float(end[1] - p[1]), float(end[0] - p[0]))
    if len(path) > 1 and float(np.hypot(*(end - path[0]))) > 0.05:
        return math.atan2(float(end[1] - path[0][1]), float(end[0] - path[0][0]))
    return previous


def look_around(k: int, x: float, y: float, yaw: float, turns: int) -> list[PatrolGoal]:
    """Viewpoint k's goals: the walk there arriving at `yaw`, then `turns` turns on the
    spot of 360°/turns each (none for 0)."""
    goals = [PatrolGoal(k, x, y, wrap_angle(yaw), look=False)]
    for i in range(1, turns + 1):
        goals.append(PatrolGoal(k, x, y, wrap_angle(yaw + i * 2 * math.pi / turns), True))
    return goals


def patrol_goals(route: Route, start_yaw: float, turns: int = 3) -> list[PatrolGoal]:
    """The pose goals that walk `route` and look around at each viewpoint (`turns` = 0,
    or a route with facings: no look-around)."""
    goals: list[PatrolGoal] = []
    yaw = start_yaw
    for k, (vp, path) in enumerate(zip(route.viewpoints, route.paths, strict=True)):
        if route.facings is not None:
            goals += look_around(k, float(vp[0]), float(vp[1]), route.facings[k], 0)
            continue
        yaw = _arrival_yaw(np.asarray(path, float), yaw)
        goals += look_around(k, float(vp[0]), float(vp[1]), yaw, turns)
    return goals


@dataclass
class NavPatrol:
    """Where the patrol is in its goals; see the module docstring."""

    route: Route
    goals: list[PatrolGoal]
    index: int = 0
    #: The navigation goal id of the current goal once sent ("" while not sent).
    goal_id: str = ""
    skipped: int = 0
    travelled_m: float = 0.0
    log: list[str] = field(default_factory=list)
    _last_xy: tuple[float, float] | None = None

    @property
    def done(self) -> bool:
        return self.index >= len(self.goals)

    @property
    def current(self) -> PatrolGoal | None:
        return None if self.done else self.goals[self.index]

    @property
    def viewpoint(self) -> int:
        """The viewpoint being walked to or looked around at (counting from 1)."""
        cur = self.current
        return len(self.route.viewpoints) if cur is None else cur.viewpoint + 1

    def moved_to(self, x: float, y: float) -> None:
        if self._last_xy is not None:
            self.travelled_m += math.hypot(x - self._last_xy[0], y - self._last_xy[1])
        self._last_xy = (x, y)

    def sent(self, goal_id: str) -> None:
        self.goal_id = goal_id

    def refused(self, reason: str) -> None:
        """Navigation would not take the current goal."""
        self._give_up(f"refused: {reason}")

    def finished(self, succeeded: bool, reason: str = "") -> None:
        """The current goal's navigation goal ended."""
        if succeeded:
            self._advance()
        else:
            self._give_up(reason or "failed")

    def _give_up(self, why: str) -> None:
        cur = self.current
        if cur is None:
            return
        if cur.look:
            self.log.append(f"viewpoint {cur.viewpoint + 1}: a turn {why}")
            self._advance()
            return
        self.skipped += 1
        self.log.append(f"viewpoint {cur.viewpoint + 1} skipped: {why}")
        k = cur.viewpoint
        while not self.done and self.goals[self.index].viewpoint == k:
            self.index += 1
        self.goal_id = ""

    def _advance(self) -> None:
        self.index += 1
        self.goal_id = ""
