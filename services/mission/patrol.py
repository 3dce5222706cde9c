"""The mapping patrol on the mission's `RobotPort`: a coverage route walked through navigation.

`plan_patrol(port, settings, spacing_m)` plans the route at the port's tick: over the
map's occupancy grid as of the tick (`RobotPort.occupancy`), from the base's pose, with a
viewpoint near each of the floor plan's tables and benches (`floor_supports`; without
them, the lattice alone): a `Route`, or a `PatrolRefusal` (no odometry or no grid:
`unavailable`; no free space: `no_route`).

`PatrolRunner` walks a route, one `step()` per mission tick (sim time `port.now_ns`):

1. the WBC to `walk` obeying navigation (the mode rides on the mission's cmd_vel);
2. the arm to `patrol_arm_posture` (`look`: the wrist camera up, where it sees bench tops
   the head camera cannot): asked again while the WBC cannot take it yet (`busy`,
   `unavailable`); given up, walking on with the head camera, when refused otherwise,
   unanswered, failed, or not there within `ARM_WAIT_S` of sim time;
3. each of `patrol_goals`' goals as a `PoseGoal` to navigation, the next once
   `nav/status` says the current one ended (a walk refused or failed skips its viewpoint,
   a failed turn is passed over); navigation refusing with a typed error (it cannot take
   goals at all) fails the patrol `navigation_failed`, no answer `unavailable`;
4. done, stopped (`stop`) or failed (`fail`): the navigation goal cancelled, the WBC to
   `stand`, the arm back to `stow`.

`status(b)` is its `PatrolStatus`, `arm_look` true while it holds the arm in `look` (the
map then fuses the wrist camera too). Goals carry the tick and take effect one mission
latency later, and navigation's and the WBC's status are read as of the tick (the port
does both): a patrol in lockstep is as repeatable as a fetch. No transport here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from common.config import MissionSettings
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.mission import PatrolReason, PatrolState, PatrolStatus
from common.messages.navigation import PoseGoal
from common.messages.wbc import Posture
from services.mission.coverage import Route, coverage_route, support_targets
from services.mission.patrol_goals import NavPatrol, patrol_goals
from services.mission.ports import PortError, Refused, RobotPort, Unavailable

log = logging.getLogger("dume.mission.patrol")

#: How far navigation may move a viewpoint (walk) or a look-around turn to a pose its
#: footprint fits, m: a viewpoint is only a place to look from (the hall patrol skipped
#: two, "in an obstacle", at 0.3 m). One value, so the turns find the walk's pose again.
POSITION_TOLERANCE_M = 0.5
TURN_TOLERANCE_RAD = 0.2
#: Turns on the spot at each viewpoint (with `patrol_look_around`): 120° each.
LOOK_TURNS = 3
TERMINAL = ("succeeded", "failed", "cancelled")
#: Sim seconds the patrol waits for the arm to reach its posture before it walks anyway.
ARM_WAIT_S = 20.0

Say = Callable[[str], None]


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


class PatrolRunner:
    """One patrol at a time; `state`, `reason` and `detail` say where it stands."""

    def __init__(self, port: RobotPort, settings: MissionSettings, say: Say = log.info) -> None:
        self.port, self.settings, self.say = port, settings, say
        self.walker: NavPatrol | None = None
        self.state: PatrolState = "idle"
        self.reason: PatrolReason = ""
        self.detail = ""
        self._started = False
        self._stop = ""
        #: Whether the arm is still to reach its patrol posture before walking (False
        #: once there or given up), the WBC's goal id once sent, and since when (ns).
        self._arm_pending = False
        self._arm_goal = ""
        self._arm_since_ns = 0
        self._arm_in_look = False

    @property
    def running(self) -> bool:
        return self.state == "running"

    @property
    def arm_look(self) -> bool:
        """The patrol holds the arm in `look` now (the wrist camera sees bench tops)."""
        return self.running and self._arm_in_look

    @property
    def route(self) -> Route | None:
        return None if self.walker is None else self.walker.route

    def start(self, route: Route) -> None:
        """Walk `route` from the next `step` (the first goal faces along its first path)."""
        turns = LOOK_TURNS if self.settings.patrol_look_around else 0
        yaw = self.port.robot_yaw() or 0.0
        self.walker = NavPatrol(route, patrol_goals(route, yaw, turns))
        self.state, self.reason, self.detail = "running", "", ""
        self._started, self._stop = False, ""
        self._arm_pending, self._arm_goal, self._arm_in_look = True, "", False

    def stop(self, why: str = "stopped by a request") -> None:
        """End at the next `step`: the goal cancelled, the arm stowed, standing."""
        if self.running:
            self._stop = why

    def fail(self, reason: PatrolReason, detail: str) -> None:
        """End now, failed for `reason`."""
        if self.running:
            self._end("failed", reason, detail)

    def status(self, b: int) -> PatrolStatus:
        w = self.walker
        return PatrolStatus(
            stamp_ns=b,
            state=self.state,
            waypoint=0 if w is None else w.viewpoint,
            waypoints=0 if w is None else len(w.route.viewpoints),
            travelled_m=0.0 if w is None else w.travelled_m,
            arm_look=self.arm_look,
            reason=self.reason,
            detail=self.detail,
        )

    def step(self) -> None:
        """One tick of a running patrol (nothing when none runs)."""
        w = self.walker
        if w is None or not self.running:
            return
        b = self.port.now_ns
        if not self._started:
            self.port.set_mode("walk", "navigation")
            self._started, self._arm_since_ns = True, b
        if self._stop or w.done:
            self._end("stopped" if self._stop else "done", detail=self._stop)
            return
        if self._arm_pending:
            self._step_arm(b)
            if self._arm_pending:
                return
        xy = self.port.robot_xy()
        if xy is None:
            return
        w.moved_to(*xy)
        self._step_nav(w)
        if self.running and w.done:
            self._end("done")

    def _step_arm(self, b: int) -> None:
        """Send the arm its patrol posture (again while the WBC cannot take it yet) and
        clear `_arm_pending` once it is there, failed, or `ARM_WAIT_S` passed."""
        name = self.settings.patrol_arm_posture
        if b - self._arm_since_ns > ARM_WAIT_S * NS_PER_S:
            self.say(f"the arm did not reach {name} in {ARM_WAIT_S:.0f} s: walking on")
            self._arm_pending = False
            return
        if not self._arm_goal:
            try:
                self._arm_goal = self.port.send_arm_goal(Posture(name=name))
            except Refused as exc:
                if exc.code in ("unavailable", "busy"):  # the WBC not in walk yet: next tick
                    log.info("patrol: arm posture %s not taken yet: %s", name, exc)
                    return
                self.say(f"arm posture {name} refused: {exc}: walking on")
                self._arm_pending = False
            except Unavailable as exc:
                self.say(f"no arm posture ({exc}): walking on")
                self._arm_pending = False
            return
        goal = self.port.arm_goal(self._arm_goal)
        if goal is None or goal.state not in TERMINAL:
            return
        if goal.state == "succeeded":
            self.say(f"arm in {name} at {b / NS_PER_S:.1f} s")
            self._arm_in_look = name == "look"
        else:
            self.say(f"arm posture {name} {goal.state}: {goal.reason}: walking on")
        self._arm_pending = False

    def _step_nav(self, w: NavPatrol) -> None:
        if w.goal_id:
            st = self.port.nav_status(w.goal_id)
            if st is not None and st.state in TERMINAL:
                ok = st.state == "succeeded"
                if not ok:
                    log.info("patrol goal %s %s: %s %s", w.goal_id, st.state, st.reason, st.detail)
                w.finished(ok, f"{st.state}: {st.reason} {st.detail}".strip())
            if w.goal_id:
                return
        goal = w.current
        if goal is None:
            return
        pose = PoseGoal(
            x=goal.x,
            y=goal.y,
            yaw=goal.yaw,
            position_tolerance_m=POSITION_TOLERANCE_M,
            yaw_tolerance_rad=TURN_TOLERANCE_RAD,
        )
        try:
            w.sent(self.port.send_nav_goal(pose))
        except Refused as exc:
            if exc.code:  # a typed error: navigation cannot take goals at all
                self._end("failed", "navigation_failed", f"navigation refused the patrol: {exc}")
                return
            log.info("patrol: viewpoint %d goal refused: %s", goal.viewpoint + 1, exc)
            w.refused(str(exc))
        except Unavailable as exc:
            self._end("failed", "unavailable", f"navigation does not answer: {exc}")

    def _stow_arm(self) -> None:
        """Fold the arm back after a patrol that raised it (the WBC finishes it in stand)."""
        if self.settings.patrol_arm_posture == "stow":
            return
        try:
            self.port.send_arm_goal(Posture(name="stow"))
        except PortError as exc:
            self.say(f"could not stow the arm: {exc}")

    def _end(
        self,
        state: Literal["done", "stopped", "failed"],
        reason: PatrolReason = "",
        detail: str = "",
    ) -> None:
        w = self.walker
        if w is not None and w.goal_id:
            self.port.cancel_nav(w.goal_id, f"patrol {state}")
        self.port.set_mode("stand", "navigation")
        self._arm_pending = False
        self._stow_arm()
        skipped = 0 if w is None else w.skipped
        if skipped:
            detail = "; ".join(filter(None, (detail, f"{skipped} viewpoint(s) skipped")))
        self.state, self.reason, self.detail = state, reason, detail
        walked = 0.0 if w is None else w.travelled_m
        self.say(
            f"patrol {state} at {self.port.now_ns / NS_PER_S:.1f} s: {walked:.1f} m walked"
            + (f" ({reason + ': ' if reason else ''}{detail})" if reason or detail else "")
        )
        if w is not None:
            for line in w.log:
                self.say(line)
