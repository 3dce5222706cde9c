"""Exploration from nothing on the mission's `RobotPort`: frontier after frontier.

`ExploreRunner` is a `goal_job.GoalJob` (the WBC to `walk` obeying navigation, the arm
to `explore_arm_posture` first, pose goals through navigation, the end) whose goals come
one at a time, one `step()` per mission tick:

1. at the start and each time the last goal ended, it reads the map's occupancy grid as
   of the tick (`RobotPort.occupancy`) and asks `frontiers.survey` for the next goal
   from the robot's pose, leaving out the goals that failed (blacklisted), what it
   already looked at, and frontiers farther than `explore_radius_m` from where it
   started (when set; `explore_*` settings);
2. a goal is a walk there facing its frontier, then `LOOK_TURNS` turns on the spot (a
   `NavPatrol` of one viewpoint); navigation refusing or failing the walk blacklists it;
3. standing on floor the map does not know (at the start: the head camera never sees the
   floor under the base, and navigation plans from no unknown cell), it steps out by
   itself on the mission's cmd_vel (mode `walk` obeying `mission`): a turn on the spot
   (the camera sees the floor round it), then, still on unknown floor, a straight walk
   onto the nearest clear seen floor (`frontiers.step_out_target`); then navigation
   again. No such floor after `MAX_STEP_OUTS` turns: failed `no_route`;
4. it ends `done` when no reachable frontier is left (the detail: goals walked, the
   known-free floor, frontiers left that no goal can see), or when the last
   `explore_stall_goals` goals together added less than `explore_stall_m2` of known
   floor (what is left are corners and gaps behind furniture: in the hall of seed 1 the
   last 20 of 46 goals added under 2 m², 500 s of sim time, while stretches of 3-5
   goals that add little come between big gains); failed `budget` when
   `explore_max_goals` goals were chosen and a reachable frontier is left, or when
   `explore_max_s` of sim time passed (even during a goal); failed `unavailable` when
   the map's grid did not come in `GRID_TRIES` ticks in a row.

`known_m2()`, `progress()` and `summary()` say how far it got. No transport here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from common.config import MissionSettings
from common.geometry import wrap_angle
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.semantic_map import OccupancyGrid
from common.robot import Footprint
from services.mission.coverage import Route
from services.mission.frontiers import FrontierGoal, FrontierParams, Survey, step_out_target, survey
from services.mission.goal_job import LOOK_TURNS, GoalJob, Say, log
from services.mission.patrol_goals import NavPatrol, look_around
from services.mission.ports import PortError, RobotPort

Point = tuple[float, float]

#: Navigation's lethal inflation is the footprint's half width plus 0.06 m
#: (`navigation.costmap.CostParams.lethal_margin_m`); the explore keeps 2 cm more.
PASS_MARGIN_M = 0.08
#: The step-out: its turn's rate (rad/s), its walk's speed (m/s), how close is there (m),
#: how long each may take and how long the WBC may take to obey the mission (s of sim
#: time), and how many turns before the explore gives up on leaving unknown floor.
STEP_TURN_WZ = 0.5
STEP_WALK_V = 0.3
STEP_ARRIVED_M = 0.1
STEP_TURN_S = 30.0
STEP_WALK_S = 20.0
MODE_WAIT_S = 5.0
MAX_STEP_OUTS = 3
#: Ticks in a row without the map's grid before the explore fails `unavailable`.
GRID_TRIES = 3


def frontier_params(settings: MissionSettings, fp: Footprint) -> FrontierParams:
    """The frontiers' choices from the settings and the robot's footprint."""
    s = settings
    return FrontierParams(
        min_frontier_m=s.explore_min_frontier_m,
        clearance_m=s.explore_clearance_m,
        pass_m=fp.half_width + PASS_MARGIN_M,
        gain=s.explore_gain,
        blacklist_m=s.explore_blacklist_m,
        seen_m=s.explore_seen_m,
    )


@dataclass
class _StepOut:
    """The step-out under way: a turn on the spot or a walk to `target`, since when (ns)."""

    phase: Literal["turn", "walk"]
    since_ns: int
    target: Point | None = None
    turned: float = 0.0
    last_yaw: float | None = None
    obeyed: bool = False


@dataclass
class _Tally:
    """What the explore did: goals chosen and walked, the places looked around from (the
    goals and where the robot stood), the frontier points looked at, the goals failed;
    the current goal."""

    chosen: int = 0
    walked: int = 0
    looked: list[Point] = field(default_factory=list)
    aimed: list[Point] = field(default_factory=list)
    failed: list[Point] = field(default_factory=list)
    goal: FrontierGoal | None = None
    #: The known-free floor at each plan that found a goal (m²): what the goals added.
    known: list[float] = field(default_factory=list)


class ExploreRunner(GoalJob):
    """One exploration at a time; `state`, `reason` and `detail` say where it stands."""

    task = "explore"

    def __init__(
        self,
        port: RobotPort,
        settings: MissionSettings,
        say: Say = log.info,
        footprint: Footprint | None = None,
    ) -> None:
        super().__init__(port, settings.explore_arm_posture, say)
        self.settings = settings
        self.fp = footprint or Footprint.stowed()
        self.params = frontier_params(settings, self.fp)
        self.walker: NavPatrol | None = None
        self.tally = _Tally()
        self.last: Survey | None = None
        self._step: _StepOut | None = None
        self._step_outs = 0
        self._just_turned = False
        self._grid_misses = 0
        self._since_ns = 0
        self._start_xy: Point | None = None

    def start(self) -> None:
        """Explore from the next `step`."""
        self.arm_posture = self.settings.explore_arm_posture
        self.walker, self.tally, self.last = None, _Tally(), None
        self._step, self._step_outs, self._just_turned = None, 0, False
        self._grid_misses, self._since_ns = 0, self.port.now_ns
        self._start_xy = self.port.robot_xy()
        self._begin()

    # -- how far it got -------------------------------------------------------------------

    def known_m2(self) -> float:
        return 0.0 if self.last is None else self.last.known_free_m2

    def progress(self) -> float:
        """The share of its budget spent (goals or sim time, whichever is further): an
        exploration cannot know how much is left to see."""
        s = self.settings
        spent_s = (self.port.now_ns - self._since_ns) / NS_PER_S
        return min(1.0, max(self.tally.chosen / s.explore_max_goals, spent_s / s.explore_max_s))

    def summary(self) -> str:
        t = self.tally
        left = 0 if self.last is None else self.last.clusters
        return (
            f"{t.walked} goal(s) walked of {t.chosen} chosen ({len(t.failed)} failed), "
            f"{self.known_m2():.1f} m² known, {left} frontier(s) left"
        )

    def _counts(self) -> tuple[int, int]:
        return self.tally.walked, self.tally.chosen

    def _last_walker(self) -> NavPatrol | None:
        return self.walker

    # -- the job --------------------------------------------------------------------------

    def _walker(self) -> NavPatrol | None:
        limit_s = self.settings.explore_max_s
        if (self.port.now_ns - self._since_ns) / NS_PER_S > limit_s:
            self._end("failed", "budget", f"its budget of {limit_s:g} s ran out: {self.summary()}")
            return None
        if self._step is not None:
            self._step_out(self.port.now_ns)
            return None
        w = self.walker
        if w is not None and not w.done:
            return w
        return self._plan()

    def _walked(self, w: NavPatrol) -> None:
        """One goal and its look-around ended: looked from there, or failed (blacklisted)."""
        goal = self.tally.goal
        if goal is None:
            return
        if w.skipped:
            self.tally.failed.append((goal.x, goal.y))
            self.say(f"explore goal {self.tally.chosen} ({goal.x:.2f}, {goal.y:.2f}) failed "
                     f"({'; '.join(w.log)}): left out from now on")  # fmt: skip
        else:
            self.tally.walked += 1
            self.tally.looked += [(goal.x, goal.y), self.port.robot_xy() or (goal.x, goal.y)]
            self.tally.aimed.append(goal.aim_xy)

    def _plan(self) -> NavPatrol | None:
        """The next goal's walker from the map as of the tick, or None (ended, stepping
        out, or the grid did not come this tick)."""
        xy = self.port.robot_xy()
        if xy is None:
            return None
        try:
            grid = self.port.occupancy()
        except PortError as exc:
            self._grid_misses += 1
            if self._grid_misses >= GRID_TRIES:
                self._end("failed", "unavailable", f"the map's occupancy grid did not come: {exc}")
            return None
        self._grid_misses = 0
        t = self.tally
        self.last = found = survey(
            np.asarray(as_numpy(grid.cells), np.uint8), grid.resolution_m, grid.origin_xy, xy,
            self.params, t.failed, t.looked, t.aimed, self._within(),
            self.settings.explore_bounds,
        )  # fmt: skip
        n, least = self.settings.explore_stall_goals, self.settings.explore_stall_m2
        if found.goal is not None:
            t.known.append(found.known_free_m2)
        if found.goal is not None and n and len(t.known) > n:
            added = t.known[-1] - t.known[-1 - n]
            if added < least:
                self._end("done", detail=f"the last {n} goals added {added:.1f} m² of floor "
                          f"(less than {least:g}): {self.summary()}")  # fmt: skip
                return None
        if found.goal is None:
            if not found.robot_on_known:
                self._leave_unknown(grid, xy)
                return None
            unseen = f"; {found.clusters} frontier(s) no goal can see" if found.clusters else ""
            self._end("done", detail=f"no reachable frontier left: {self.summary()}{unseen}")
            return None
        if t.chosen >= self.settings.explore_max_goals:
            said = f"its budget of {t.chosen} goals ran out: {self.summary()}"
            self._end("failed", "budget", said)
            return None
        g = found.goal
        t.chosen += 1
        t.goal = g
        self._just_turned = False
        route = Route([np.array([g.x, g.y])], [np.array([xy, (g.x, g.y)])])
        self.walker = NavPatrol(route, look_around(0, g.x, g.y, g.yaw, LOOK_TURNS))
        self.say(
            f"explore goal {t.chosen}: ({g.x:.2f}, {g.y:.2f}) facing {math.degrees(g.yaw):.0f}°, "
            f"{g.path_m:.1f} m away, {g.distance_m:.1f} m from a frontier of {g.frontier_m:.1f} m "
            f"at ({g.frontier_xy[0]:.2f}, {g.frontier_xy[1]:.2f}); {self.summary()}"
        )
        return self.walker

    # -- off unknown floor ------------------------------------------------------------------

    def _within(self) -> tuple[Point, float] | None:
        """The disc the exploration keeps to (`explore_radius_m` about where it started)."""
        r = self.settings.explore_radius_m
        return None if r <= 0 or self._start_xy is None else (self._start_xy, r)

    def _leave_unknown(self, grid: OccupancyGrid, xy: Point) -> None:
        """The robot stands on floor the map does not know: a turn on the spot first, then
        a walk onto seen floor; `no_route` when neither helps (module docstring, 3)."""
        b = self.port.now_ns
        if not self._just_turned:
            if self._step_outs >= MAX_STEP_OUTS:
                self._end("failed", "no_route", f"the robot stands on floor the map does not "
                          f"know after {MAX_STEP_OUTS} turns on the spot")  # fmt: skip
                return
            self._step_outs += 1
            self.say(f"standing on floor the map does not know: a turn on the spot "
                     f"({self._step_outs} of {MAX_STEP_OUTS})")  # fmt: skip
            self._step = _StepOut("turn", b)
            self.port.set_mode("walk", "mission")
            return
        target = step_out_target(
            np.asarray(as_numpy(grid.cells), np.uint8), grid.resolution_m, grid.origin_xy, xy,
            self.params.pass_m, self.fp.half_width,
        )  # fmt: skip
        if target is None:
            self._end("failed", "no_route", "the robot stands on floor the map does not know, "
                      "and no clear seen floor is within 2 m to step onto")  # fmt: skip
            return
        self.say(f"stepping out onto seen floor at ({target[0]:.2f}, {target[1]:.2f})")
        self._just_turned = False
        self._step = _StepOut("walk", b, target)
        self.port.set_mode("walk", "mission")

    def _step_out(self, b: int) -> None:
        """One tick of the step-out's turn or walk on the mission's cmd_vel."""
        s = self._step
        assert s is not None
        status = self.port.wbc_status()
        if not s.obeyed:
            mode = None if status is None else (status.mode, status.cmd_vel_source)
            s.obeyed = mode == ("walk", "mission")
            if not s.obeyed:
                if b - s.since_ns > MODE_WAIT_S * NS_PER_S:
                    self._end("failed", "unavailable", "the controller did not take walk "
                              f"from the mission in {MODE_WAIT_S:g} s")  # fmt: skip
                return
            s.since_ns = b
        xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
        if xy is None or yaw is None:
            return
        elapsed = (b - s.since_ns) / NS_PER_S
        if s.phase == "turn":
            if s.last_yaw is not None:
                s.turned += wrap_angle(yaw - s.last_yaw)
            s.last_yaw = yaw
            if abs(s.turned) >= 2 * math.pi or elapsed > STEP_TURN_S:
                self._just_turned = True
                self._stepped(f"turned {math.degrees(s.turned):.0f}° on the spot")
                return
            self.port.command_velocity(0.0, 0.0, STEP_TURN_WZ)
            return
        assert s.target is not None
        dx, dy = s.target[0] - xy[0], s.target[1] - xy[1]
        dist = math.hypot(dx, dy)
        if dist < STEP_ARRIVED_M or elapsed > STEP_WALK_S:
            self._stepped(f"stepped out to ({xy[0]:.2f}, {xy[1]:.2f}), {dist:.2f} m from "
                          "its target")  # fmt: skip
            return
        err = wrap_angle(math.atan2(dy, dx) - yaw)
        wz = float(np.clip(1.5 * err, -STEP_TURN_WZ, STEP_TURN_WZ))
        vx = 0.0 if abs(err) > 0.3 else min(STEP_WALK_V, 0.8 * dist)
        self.port.command_velocity(vx, 0.0, wz)

    def _stepped(self, said: str) -> None:
        self.port.command_velocity(0.0, 0.0, 0.0)
        self.port.set_mode("walk", "navigation")
        self._step = None
        self.say(said)
