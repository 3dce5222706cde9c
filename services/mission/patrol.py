"""The mapping patrol on the mission's `RobotPort`: a coverage route walked through navigation.

`plan_patrol(port, settings, spacing_m)` plans the route at the port's tick: over the
map's occupancy grid as of the tick (`RobotPort.occupancy`), from the base's pose, with a
viewpoint near each of the floor plan's tables and benches (`floor_supports`; without
them, the lattice alone): a `Route`, or a `PatrolRefusal` (no odometry or no grid:
`unavailable`; no free space: `no_route`).

`PatrolRunner` walks a route, one `step()` per mission tick, as a `goal_job.GoalJob`
(the WBC to `walk` obeying navigation, the arm to `patrol_arm_posture` first, each of
`patrol_goals`' goals as a `PoseGoal` to navigation, the end): done once the route's
last goal ended. No transport here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.config import MissionSettings
from common.messages import as_numpy
from common.messages.mission import PatrolReason
from services.mission.coverage import Route, coverage_route, support_targets
from services.mission.goal_job import ARM_WAIT_S, LOOK_TURNS, GoalJob, Say, log
from services.mission.patrol_goals import NavPatrol, patrol_goals
from services.mission.ports import PortError, RobotPort

__all__ = ["ARM_WAIT_S", "PatrolRefusal", "PatrolRunner", "plan_patrol"]


@dataclass(frozen=True)
class PatrolRefusal:
    """Why no patrol can start: the typed reason and a sentence."""

    reason: PatrolReason
    detail: str


def plan_patrol(
    port: RobotPort, settings: MissionSettings, spacing_m: float = 0.0, say: Say = log.info
) -> Route | PatrolRefusal:
    """The coverage route from the base's pose at the port's tick (module docstring)."""
    xy = port.robot_xy()
    if xy is None or port.robot_yaw() is None:
        return PatrolRefusal("unavailable", "no odometry: is the sim running?")
    try:
        grid = port.occupancy()
    except PortError as exc:
        return PatrolRefusal("unavailable", f"the map's occupancy grid did not come: {exc}")
    try:
        surfaces = port.floor_supports()
    except PortError as exc:
        say(f"no floor plan's supports ({exc}): the viewpoints' lattice only")
        surfaces = []
    s = settings
    route = coverage_route(
        np.asarray(as_numpy(grid.cells), np.uint8),
        grid.resolution_m,
        grid.origin_xy,
        xy,
        spacing_m or s.patrol_spacing_m,
        s.patrol_clearance_m,
        support_targets(surfaces) if surfaces else None,
        s.patrol_see_m,
    )
    if not route.viewpoints:
        return PatrolRefusal("no_route", "no free space to patrol in the map's grid")
    return route


class PatrolRunner(GoalJob):
    """One patrol at a time; `state`, `reason` and `detail` say where it stands."""

    task = "patrol"

    def __init__(self, port: RobotPort, settings: MissionSettings, say: Say = log.info) -> None:
        super().__init__(port, settings.patrol_arm_posture, say)
        self.settings = settings
        self.walker: NavPatrol | None = None

    @property
    def route(self) -> Route | None:
        return None if self.walker is None else self.walker.route

    def start(self, route: Route) -> None:
        """Walk `route` from the next `step` (the first goal faces along its first path)."""
        turns = LOOK_TURNS if self.settings.patrol_look_around else 0
        yaw = self.port.robot_yaw() or 0.0
        self.arm_posture = self.settings.patrol_arm_posture
        self.walker = NavPatrol(route, patrol_goals(route, yaw, turns))
        self._begin()

    def _walker(self) -> NavPatrol | None:
        w = self.walker
        if w is not None and w.done:
            self._end("done")
            return None
        return w

    def _walked(self, w: NavPatrol) -> None:
        self._end("done")

    def _last_walker(self) -> NavPatrol | None:
        return self.walker

    def _counts(self) -> tuple[int, int]:
        w = self.walker
        return (0, 0) if w is None else (w.viewpoint, len(w.route.viewpoints))
