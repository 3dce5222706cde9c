"""The mapping patrol on the mission's `RobotPort`: a coverage route walked through navigation.

`plan_patrol(port, settings, spacing_m)` plans the route at the port's tick: over the
map's occupancy grid as of the tick (`RobotPort.occupancy`), from the base's pose, with a
viewpoint near each of the floor plan's tables and benches (`floor_supports`; without
them, the lattice alone): a `Route`, or a `PatrolRefusal` (no odometry or no grid:
`unavailable`; no free space: `no_route`). With `surfaces=True` (the semantic pass after
an exploration) it is `coverage.facing_route` on the surfaces' targets: viewpoints
facing the surfaces the map saw, seen from `patrol_near_m`-`patrol_see_m` within the
wrist camera's view less a margin (`VIEW_HALF_ANGLE`); with no surface in the map, the
lattice.

`in_doubt(artifacts, settings)` names the map's artifacts whose class or place a person
would want to look at again (seen only from afar or a few times; two classes at one
place), and
`plan_second_look` the route that faces them from nearer (`coverage.facing_route`): the
semantic pass's last stage (`patrol_desk`).

`PatrolRunner` walks a route, one `step()` per mission tick, as a `goal_job.GoalJob`
(the WBC to `walk` obeying navigation, the arm to `patrol_arm_posture` first, each of
`patrol_goals`' goals as a `PoseGoal` to navigation, the end): done once the route's
last goal ended. No transport here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.config import MissionSettings
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.mission import PatrolReason
from common.messages.semantic_map import MapEntity
from common.robot_description import CAMERA_MOUNTS
from services.mission.coverage import (
    Route,
    coverage_route,
    facing_route,
    support_targets,
)
from services.mission.goal_job import ARM_WAIT_S, LOOK_TURNS, GoalJob, Say, log
from services.mission.patrol_goals import NavPatrol, patrol_goals
from services.mission.ports import PortError, RobotPort

__all__ = ["ARM_WAIT_S", "PatrolRefusal", "PatrolRunner", "plan_patrol"]


def _half_view(camera: str, margin_rad: float) -> float:
    """Half the camera's horizontal field of view (its fovy is vertical), less a margin."""
    mount = CAMERA_MOUNTS[camera]
    tan_v = math.tan(math.radians(mount.fovy_deg) / 2.0)
    return math.atan(tan_v * mount.width / mount.height) - margin_rad


#: A surface's target counts as seen within this of the wrist camera's facing (rad): its
#: half view is 36.5°; 6.5° less keeps a can at the image's edge out of the count.
VIEW_HALF_ANGLE = _half_view("camera_wrist", math.radians(6.5))


@dataclass(frozen=True)
class PatrolRefusal:
    """Why no patrol can start: the typed reason and a sentence."""

    reason: PatrolReason
    detail: str


def plan_patrol(
    port: RobotPort,
    settings: MissionSettings,
    spacing_m: float = 0.0,
    say: Say = log.info,
    surfaces: bool = False,
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
        found = port.floor_supports()
    except PortError as exc:
        say(f"no floor plan's supports ({exc}): the viewpoints' lattice only")
        found = []
    s = settings
    cells = np.asarray(as_numpy(grid.cells), np.uint8)
    if surfaces and found:
        route = facing_route(
            cells, grid.resolution_m, grid.origin_xy, xy, support_targets(found),
            s.patrol_clearance_m,
            s.patrol_near_m, s.patrol_see_m, VIEW_HALF_ANGLE,
        )  # fmt: skip
        unseen = f"; {route.unseen} of their targets no viewpoint sees" if route.unseen else ""
        say(f"semantic pass: {len(route.viewpoints)} viewpoints facing {len(found)} "
            f"surfaces{unseen}")  # fmt: skip
        if route.viewpoints:
            return route
    if surfaces:
        say("no surface to look at from the known floor: the viewpoints' lattice")
    route = coverage_route(
        cells,
        grid.resolution_m,
        grid.origin_xy,
        xy,
        spacing_m or s.patrol_spacing_m,
        s.patrol_clearance_m,
        support_targets(found) if found else None,
        s.patrol_see_m,
    )
    if not route.viewpoints:
        return PatrolRefusal("no_route", "no known free floor to patrol in the map's grid")
    return route


def in_doubt(artifacts: list[MapEntity], settings: MissionSettings) -> dict[str, str]:
    """The artifacts the map made itself that are worth a second look, with why: seen
    only from beyond `patrol_recheck_beyond_m`, seen fewer than `patrol_recheck_below`
    times, or within `patrol_recheck_pair_m` of an artifact of another class."""
    s = settings
    mine = [a for a in artifacts if a.source == "perception"]
    out: dict[str, str] = {}
    for a in mine:
        far = a.nearest_view_m
        if far is not None and far > s.patrol_recheck_beyond_m:
            out[a.id] = f"seen only from {far:.1f} m"
        elif a.observations < s.patrol_recheck_below:
            out[a.id] = f"seen {a.observations} times"
        for b in mine:
            d = math.dist(a.position_in_world[:2], b.position_in_world[:2])
            if b.class_name != a.class_name and d < s.patrol_recheck_pair_m:
                out.setdefault(a.id, f"{d:.2f} m from {b.id}")
    return out


def plan_second_look(
    port: RobotPort, settings: MissionSettings, say: Say = log.info
) -> Route | None:
    """The route facing the artifacts in doubt from within `patrol_recheck_see_m`, or
    None (none in doubt, none seen from the known floor, or the map did not answer)."""
    xy = port.robot_xy()
    try:
        artifacts = port.mapped_artifacts()
        grid = port.occupancy() if xy is not None else None
    except PortError as exc:
        say(f"no second look: the map did not answer ({exc})")
        return None
    doubt = in_doubt(artifacts, settings)
    if not doubt or xy is None or grid is None:
        return None
    where = np.array([a.position_in_world[:2] for a in artifacts if a.id in doubt])
    s = settings
    route = facing_route(
        np.asarray(as_numpy(grid.cells), np.uint8), grid.resolution_m, grid.origin_xy, xy,
        where, s.patrol_clearance_m, s.patrol_near_m, s.patrol_recheck_see_m, VIEW_HALF_ANGLE,
    )  # fmt: skip
    said = ", ".join(f"{k} ({why})" for k, why in sorted(doubt.items()))
    unseen = f"; {route.unseen} no viewpoint sees" if route.unseen else ""
    say(f"second look: {len(route.viewpoints)} viewpoints for {said}{unseen}")
    return route if route.viewpoints else None


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
        turns = LOOK_TURNS if self.settings.patrol_look_around else 0  # none with facings
        yaw = self.port.robot_yaw() or 0.0
        self.arm_posture = self.settings.patrol_arm_posture
        facing = route.facings is not None
        self.dwell_ns = round(self.settings.patrol_dwell_s * NS_PER_S) if facing else 0
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
