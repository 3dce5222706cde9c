"""A mapping job on the mission's `RobotPort`: pose goals walked through navigation.

The mapping patrol (`patrol.PatrolRunner`: a coverage route planned once) and the
exploration (`explore.ExploreRunner`: the next frontier each time a goal ended) are two
such jobs; `GoalJob` is what they share, one `step()` per mission tick (sim time
`port.now_ns`):

1. the WBC to `walk` obeying navigation (the mode rides on the mission's cmd_vel);
2. the arm to the job's posture (`look`: the wrist camera up, where it sees bench tops
   the head camera cannot; `stow`): asked again while the WBC cannot take it yet
   (`busy`, `unavailable`); given up, walking on with the head camera, when refused
   otherwise, unanswered, failed, or not there within `ARM_WAIT_S` of sim time;
3. the goals of the walker the job gives (`_walker()`, a `NavPatrol`: a walk to each
   viewpoint, then turns on the spot), each a `PoseGoal` to navigation, the next once
   `nav/status` says the current one ended (a walk refused or failed skips its
   viewpoint, a failed turn is passed over); navigation refusing with a typed error (it
   cannot take goals at all) fails the job `navigation_failed`, no answer `unavailable`;
   after a walk that arrived, the job holds there `dwell_ns` (0 but for a route that
   faces what it came for) before the next goal or its end, so the map gets its looks;
   a walk held up `HELD_UP_S` within `POSITION_TOLERANCE_M` of its goal has arrived
   (navigation's goal cancelled: people crossing, or the last of a turn refused);
4. done, stopped (`stop`) or failed (`fail`): the navigation goal cancelled, the WBC to
   `stand`, the arm back to `stow`.

`status(b)` is its `PatrolStatus`, `arm_look` true while it holds the arm in `look` (the
map then fuses the wrist camera too). Goals carry the tick and take effect one mission
latency later, and navigation's and the WBC's status are read as of the tick (the port
does both): a job in lockstep is as repeatable as a fetch. No transport here.
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Literal

from common.messages.base import NS_PER_S
from common.messages.mission import JobTask, PatrolReason, PatrolState, PatrolStatus
from common.messages.navigation import PoseGoal
from common.messages.wbc import Posture
from services.mission.patrol_goals import NavPatrol
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
#: Sim seconds a job waits for the arm to reach its posture before it walks anyway.
ARM_WAIT_S = 20.0
#: A walk whose goal the robot stands within `POSITION_TOLERANCE_M` of for this long,
#: sim s, without navigation saying it arrived, has arrived: a viewpoint is a place to
#: look from. Hall seed 4's shift: the search's robot stood 6 cm from a viewpoint for
#: 105 s, its last 35° of turn refused by the body guard (a map cell at its flank) and
#: its steps clear by the people caps of two workers crossing there.
HELD_UP_S = 15.0

Say = Callable[[str], None]
Ending = Literal["done", "stopped", "failed"]
#: The arm's postures a job may hold while it walks.
JobPosture = Literal["look", "stow"]


class GoalJob(ABC):
    """One job's life; `state`, `reason` and `detail` say where it stands. A job is
    `task` (`patrol`, `explore`); it holds the arm in `arm_posture` while it runs."""

    task: JobTask = "patrol"

    def __init__(self, port: RobotPort, arm_posture: JobPosture, say: Say = log.info) -> None:
        self.port, self.arm_posture, self.say = port, arm_posture, say
        self.state: PatrolState = "idle"
        self.reason: PatrolReason = ""
        self.detail = ""
        self.travelled_m = 0.0
        self._last_xy: tuple[float, float] | None = None
        self._started = False
        self._stop = ""
        #: Whether the arm is still to reach the job's posture before walking (False once
        #: there or given up), the WBC's goal id once sent, and since when (ns).
        self._arm_pending = False
        self._arm_goal = ""
        self._arm_since_ns = 0
        self._arm_in_look = False
        #: How long the job holds at a viewpoint it walked to, and until when, ns.
        self.dwell_ns = 0
        self._hold_until_ns = 0
        self._near_since_ns = 0  # the current walk's goal within reach since (0: not)

    # -- what a job says ------------------------------------------------------------------

    @abstractmethod
    def _walker(self) -> NavPatrol | None:
        """The goals to walk now; None: none this tick (the job may have ended itself)."""
        ...

    @abstractmethod
    def _counts(self) -> tuple[int, int]:
        """(the viewpoint being walked to or looked around at, of how many)."""
        ...

    @abstractmethod
    def _walked(self, w: NavPatrol) -> None:
        """The walker's last goal ended (the job goes on or ends)."""
        ...

    def _last_walker(self) -> NavPatrol | None:
        """The walker whose goal a job that ends must cancel, and whose skips it counts."""
        return None

    def known_m2(self) -> float:
        """The known-free floor the job last saw in the map, m² (0: it does not look)."""
        return 0.0

    # -- the life -------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        return self.state == "running"

    @property
    def arm_look(self) -> bool:
        """The job holds the arm in `look` now (the wrist camera sees bench tops)."""
        return self.running and self._arm_in_look

    def _begin(self) -> None:
        """Start from the next `step` (a subclass's `start` calls it)."""
        self.state, self.reason, self.detail = "running", "", ""
        self._started, self._stop = False, ""
        self.travelled_m, self._last_xy = 0.0, None
        self._arm_pending, self._arm_goal, self._arm_in_look = True, "", False
        self._hold_until_ns = 0

    def stop(self, why: str = "stopped by a request") -> None:
        """End at the next `step`: the goal cancelled, the arm stowed, standing."""
        if self.running:
            self._stop = why

    def fail(self, reason: PatrolReason, detail: str) -> None:
        """End now, failed for `reason`."""
        if self.running:
            self._end("failed", reason, detail)

    def status(self, b: int) -> PatrolStatus:
        waypoint, waypoints = self._counts()
        return PatrolStatus(
            stamp_ns=b,
            state=self.state,
            task=self.task,
            waypoint=waypoint,
            waypoints=waypoints,
            travelled_m=self.travelled_m,
            known_m2=round(self.known_m2(), 2),
            arm_look=self.arm_look,
            reason=self.reason,
            detail=self.detail,
        )

    def step(self) -> None:
        """One tick of a running job (nothing when none runs)."""
        if not self.running:
            return
        b = self.port.now_ns
        if not self._started:
            self.port.set_mode("walk", "navigation")
            self._started, self._arm_since_ns = True, b
        if self._stop:
            self._end("stopped", detail=self._stop)
            return
        if self._arm_pending:
            self._step_arm(b)
            if self._arm_pending:
                return
        xy = self.port.robot_xy()
        if xy is None:
            return
        if self._last_xy is not None:
            self.travelled_m += math.hypot(xy[0] - self._last_xy[0], xy[1] - self._last_xy[1])
        self._last_xy = xy
        if b < self._hold_until_ns:
            return  # holding at a viewpoint
        w = self._walker()
        if w is None or not self.running:
            return
        self._step_nav(w, b, xy)
        if self.running and w.done and b >= self._hold_until_ns:
            self._walked(w)

    def _step_arm(self, b: int) -> None:
        """Send the arm the job's posture (again while the WBC cannot take it yet) and
        clear `_arm_pending` once it is there, failed, or `ARM_WAIT_S` passed."""
        name = self.arm_posture
        if b - self._arm_since_ns > ARM_WAIT_S * NS_PER_S:
            self.say(f"the arm did not reach {name} in {ARM_WAIT_S:.0f} s: walking on")
            self._arm_pending = False
            return
        if not self._arm_goal:
            try:
                self._arm_goal = self.port.send_arm_goal(Posture(name=name))
            except Refused as exc:
                if exc.code in ("unavailable", "busy"):  # the WBC not in walk yet: next tick
                    log.info("%s: arm posture %s not taken yet: %s", self.task, name, exc)
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

    def _step_nav(self, w: NavPatrol, b: int, xy: tuple[float, float]) -> None:
        if w.goal_id:
            st = self.port.nav_status(w.goal_id)
            if (st is None or st.state not in TERMINAL) and self._held_up(w, b, xy):
                self.port.cancel_nav(w.goal_id, f"{self.task}: held up at the viewpoint")
                w.finished(True)
                self._hold_until_ns = b + self.dwell_ns
                return
            if st is not None and st.state in TERMINAL:
                ok = st.state == "succeeded"
                if not ok:
                    log.info("%s goal %s %s: %s %s", self.task, w.goal_id, st.state, st.reason,
                             st.detail)  # fmt: skip
                walk = w.current is not None and not w.current.look
                w.finished(ok, f"{st.state}: {st.reason} {st.detail}".strip())
                if ok and walk:
                    self._hold_until_ns = b + self.dwell_ns
            if w.goal_id or b < self._hold_until_ns:  # still walking, or holding there
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
        self._near_since_ns = 0
        try:
            w.sent(self.port.send_nav_goal(pose))
        except Refused as exc:
            if exc.code:  # a typed error: navigation cannot take goals at all
                self._end("failed", "navigation_failed", f"navigation refused the {self.task}: "
                          f"{exc}")  # fmt: skip
                return
            log.info("%s: viewpoint %d goal refused: %s", self.task, goal.viewpoint + 1, exc)
            w.refused(str(exc))
        except Unavailable as exc:
            self._end("failed", "unavailable", f"navigation does not answer: {exc}")

    def _held_up(self, w: NavPatrol, b: int, xy: tuple[float, float]) -> bool:
        """Whether the walk under way has arrived all the same (`HELD_UP_S`), said so;
        `xy`: the robot's place this tick."""
        goal = w.current
        if goal is None or goal.look:
            return False
        off = math.hypot(xy[0] - goal.x, xy[1] - goal.y)
        if off > POSITION_TOLERANCE_M:
            self._near_since_ns = 0
            return False
        if not self._near_since_ns:
            self._near_since_ns = b
        if b - self._near_since_ns < HELD_UP_S * NS_PER_S:
            return False
        self.say(f"viewpoint {goal.viewpoint + 1}: held up {HELD_UP_S:.0f} s within {off:.2f} m "
                 "of it: looking from here")  # fmt: skip
        return True

    def _stow_arm(self) -> None:
        """Fold the arm back after a job that raised it (the WBC finishes it in stand)."""
        if self.arm_posture == "stow":
            return
        try:
            self.port.send_arm_goal(Posture(name="stow"))
        except PortError as exc:
            self.say(f"could not stow the arm: {exc}")

    def _end(self, state: Ending, reason: PatrolReason = "", detail: str = "") -> None:
        w = self._last_walker()
        if w is not None and w.goal_id:
            self.port.cancel_nav(w.goal_id, f"{self.task} {state}")
        self.port.set_mode("stand", "navigation")
        self._arm_pending = False
        self._stow_arm()
        skipped = 0 if w is None else w.skipped
        if skipped:
            detail = "; ".join(filter(None, (detail, f"{skipped} viewpoint(s) skipped")))
        self.state, self.reason, self.detail = state, reason, detail
        self.say(
            f"{self.task} {state} at {self.port.now_ns / NS_PER_S:.1f} s: "
            f"{self.travelled_m:.1f} m walked"
            + (f" ({reason + ': ' if reason else ''}{detail})" if reason or detail else "")
        )
        if w is not None:
            for line in w.log:
                self.say(line)
