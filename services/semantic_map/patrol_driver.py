"""The mapping patrol's transport: the map node's side of `dume map --patrol`.

`PatrolDriver.step(b, odom)` runs in the map's lockstep tick. Through navigation
(`semantic_map.patrol_via = "navigation"`, the default): the WBC is put in `walk` obeying
navigation, each `NavPatrol` goal goes to `nav/goal` as a `PoseGoal` and the patrol moves
on when `nav/status` reports that goal ended (navigation takes a goal sent before its
map and fails it `timeout` if the map never comes); one that does not answer fails the
patrol. Goals go through `common.clients`.
With `patrol_via = "cmd_vel"` (when no navigation runs) a `PatrolFollower` walks the
route with cmd_vel of source `semantic_map`. Before the first step the arm goes to
`patrol_arm_posture` (`look`: the wrist camera up, where it sees bench tops the head
camera cannot) and holds it while the robot walks and turns (its footprint is inside the
stowed one); an arm that does not get there within `ARM_WAIT_S` leaves the patrol to the
head camera. When done or stopped: zero velocity, the navigation goal cancelled, the arm
sent back to `stow`, the WBC back to `stand`. Its goals and cancels carry the map's tick
and take effect one map latency later, and it reads navigation's and the WBC's status as
of the tick, as the mission does: a patrol in lockstep is as repeatable as a mission.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Literal

from common.bus import Bus
from common.clients import ArmClient, ClientError, NavClient, Refused, Unavailable
from common.config import SemanticMapSettings
from common.geometry import yaw_of_quat_xyzw
from common.keys import RobotKeys
from common.messages.base import NS_PER_S
from common.messages.navigation import NavStatus, PoseGoal
from common.messages.semantic_map import PatrolState
from common.messages.sim import Odom
from common.messages.wbc import CmdVel, Posture, WbcMode, WbcStatus
from services.semantic_map.nav_patrol import NavPatrol, patrol_goals
from services.semantic_map.patrol import PatrolFollower, Route

log = logging.getLogger("dume.semantic_map.patrol")

#: How long a goal query waits for navigation's or the WBC's answer, wall s.
GOAL_TIMEOUT_S = 5.0
#: How far navigation may move a viewpoint (walk) or a look-around turn to a pose its
#: footprint fits, m: a viewpoint is only a place to look from (the hall patrol skipped
#: two, "in an obstacle", at 0.3 m). One value, so the turns find the walk's pose again.
POSITION_TOLERANCE_M = 0.5
TURN_TOLERANCE_RAD = 0.2
TERMINAL = ("succeeded", "failed", "cancelled")
#: Sim seconds the patrol waits for the arm to reach its posture before it walks anyway.
ARM_WAIT_S = 20.0


class PatrolDriver:
    """One patrol at a time; `state` and `reason` say where it stands."""

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        cfg: SemanticMapSettings,
        name: str,
        nav_source: str,
        latency_ns: Mapping[str, int] | None = None,
    ) -> None:
        self.bus, self.keys, self.cfg, self.name = bus, keys, cfg, name
        self.nav_source = nav_source
        latency = latency_ns or {}
        #: What it sends at the map's tick b takes effect at b + the map's latency; it reads
        #: navigation's status as of b − navigation's latency (lockstep: the same run).
        self.latency_ns = latency.get(name, 0)
        self.nav_latency_ns = latency.get("navigation", 0)
        self._t = 0
        self.cmd_vel = bus.publisher(keys.cmd_vel, CmdVel, "control")
        self.mode = bus.publisher(keys.wbc_mode, WbcMode, "control")
        self.nav = NavClient(bus, keys, GOAL_TIMEOUT_S)
        self.arm = ArmClient(bus, keys, GOAL_TIMEOUT_S)
        self.nav_status = bus.latest(keys.nav_status, NavStatus, history=8)
        self.wbc_status = bus.latest(keys.wbc_status, WbcStatus, history=4)
        self.walker: NavPatrol | PatrolFollower | None = None
        self.state: PatrolState = "idle"
        self.reason = ""
        self._started = False
        self._stop = False
        #: Whether the arm is still to reach its patrol posture before walking (False
        #: once there or given up), and the WBC's goal id once sent.
        self._arm_pending = False
        self._arm_goal = ""
        self._arm_since_ns = 0
        self._arm_in_look = False

    @property
    def running(self) -> bool:
        return self.state == "running"

    @property
    def arm_up(self) -> bool:
        """The patrol holds the arm in `look` now (the wrist camera sees bench tops)."""
        return self.running and self._arm_in_look

    @property
    def route(self) -> Route | None:
        return None if self.walker is None else self.walker.route

    def start(self, route: Route, yaw: float) -> None:
        c = self.cfg
        if c.patrol_via == "navigation":
            turns = 3 if c.patrol_look_around else 0
            self.walker = NavPatrol(route, patrol_goals(route, yaw, turns))
        else:
            self.walker = PatrolFollower(
                route,
                speed=c.patrol_speed,
                turn_rate=c.patrol_turn_rate,
                look_around=c.patrol_look_around,
            )
        self.state, self.reason, self._started, self._stop = "running", "", False, False
        self._arm_pending, self._arm_goal, self._arm_in_look = True, "", False

    def stop(self) -> None:
        if self.running:
            self._stop = True

    def progress(self) -> tuple[int, int, float, int]:
        """(viewpoint, viewpoints, travelled m, skipped)."""
        w = self.walker
        if w is None:
            return 0, 0, 0.0, 0
        n = len(w.route.viewpoints)
        at = w.viewpoint if isinstance(w, NavPatrol) else min(w.leg + 1, n)
        return at, n, w.travelled_m, w.skipped

    @property
    def _effective(self) -> int:
        return self._t + self.latency_ns

    def step(self, b: int, odom: Odom | None) -> None:
        self._t = b
        w = self.walker
        if w is None or not self.running:
            return
        via_nav = isinstance(w, NavPatrol)
        if not self._started:
            source = self.nav_source if via_nav else self.name
            self.mode.put(WbcMode(stamp_ns=b, mode="walk", cmd_vel_source=source))
            self._started, self._arm_since_ns = True, b
        if self._stop or w.done:
            self._end(b, "stopped" if self._stop else "done")
            return
        if self._arm_pending:
            self._step_arm(b)
            if self._arm_pending:
                if not via_nav:
                    self.cmd_vel.put(CmdVel(stamp_ns=b, vx=0.0, vy=0.0, wz=0.0, source=self.name))
                return
        if odom is None:
            if not via_nav:
                self.cmd_vel.put(CmdVel(stamp_ns=b, vx=0.0, vy=0.0, wz=0.0, source=self.name))
            return
        x, y, _z = odom.base_position_in_world
        if isinstance(w, NavPatrol):
            w.moved_to(x, y)
            self._step_nav(b, w)
        else:
            yaw = yaw_of_quat_xyzw(odom.base_orientation_xyzw)
            vx, vy, wz = w.step(x, y, yaw, b)
            self.cmd_vel.put(CmdVel(stamp_ns=b, vx=vx, vy=vy, wz=wz, source=self.name))
        if w.done:
            self._end(b, "done")

    def _step_arm(self, b: int) -> None:
        """Send the arm its patrol posture (again while the WBC cannot take it yet) and
        clear `_arm_pending` once it is there, failed, or `ARM_WAIT_S` passed."""
        name = self.cfg.patrol_arm_posture
        if b - self._arm_since_ns > ARM_WAIT_S * NS_PER_S:
            log.warning("patrol: the arm did not reach %s in %.0f s: walking on", name, ARM_WAIT_S)
            self._arm_pending = False
            return
        if not self._arm_goal:
            try:
                self._arm_goal = self.arm.send(Posture(name=name), effective_ns=self._effective)
            except Refused as exc:
                if exc.code in ("unavailable", "busy"):  # the WBC not in walk yet: next tick
                    log.info("patrol: arm posture %s not taken yet: %s", name, exc)
                    return
                log.warning("patrol: arm posture %s refused: %s: walking on", name, exc)
                self._arm_pending = False
            except Unavailable as exc:
                log.warning("patrol: no arm posture (%s): walking on", exc)
                self._arm_pending = False
            return
        st = self.wbc_status.at(b - 1)
        goal = (
            None if st is None else next((g for g in st.goals if g.goal_id == self._arm_goal), None)
        )
        if goal is None or goal.state not in TERMINAL:
            return
        if goal.state == "succeeded":
            log.info("patrol: arm in %s at %.1f s", name, b / NS_PER_S)
            self._arm_in_look = name == "look"
        else:
            log.warning("patrol: arm posture %s %s: %s: walking on", name, goal.state, goal.reason)
        self._arm_pending = False

    def _stow_arm(self) -> None:
        """Fold the arm back after a patrol that raised it (the WBC finishes it in stand)."""
        if self.cfg.patrol_arm_posture == "stow":
            return
        try:
            self.arm.send(Posture(name="stow"), effective_ns=self._effective)
        except ClientError as exc:
            log.warning("patrol: could not stow the arm: %s", exc)

    def _step_nav(self, b: int, w: NavPatrol) -> None:
        if w.goal_id:
            st = self.nav_status.at(b - self.nav_latency_ns)
            if st is not None and st.goal_id == w.goal_id and st.state in TERMINAL:
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
            w.sent(self.nav.send(pose, stamp_ns=b, effective_ns=self._effective))
        except Refused as exc:
            if exc.code:  # a typed error: navigation cannot take goals at all
                self._end(b, "failed", f"navigation refused the patrol: {exc}")
                return
            log.info("patrol: viewpoint %d goal refused: %s", goal.viewpoint + 1, exc)
            w.refused(str(exc))
        except Unavailable as exc:
            self._end(b, "failed", f"navigation does not answer: {exc}")

    def _end(self, b: int, state: Literal["done", "stopped", "failed"], reason: str = "") -> None:
        w = self.walker
        if isinstance(w, NavPatrol):
            if w.goal_id:
                self.nav.cancel(w.goal_id, f"patrol {state}", effective_ns=self._effective)
        else:
            self.cmd_vel.put(CmdVel(stamp_ns=b, vx=0.0, vy=0.0, wz=0.0, source=self.name))
        self.mode.put(WbcMode(stamp_ns=b, mode="stand", cmd_vel_source=self.nav_source))
        self._arm_pending = False
        self._stow_arm()
        skipped = 0 if w is None else w.skipped
        if not reason and skipped:
            reason = f"{skipped} viewpoint(s) skipped"
        self.state, self.reason = state, reason
        log.info(
            "patrol %s at %.1f s: %.1f m walked%s",
            state,
            b / NS_PER_S,
            0.0 if w is None else w.travelled_m,
            f" ({reason})" if reason else "",
        )
        if w is not None:
            for line in w.log:
                log.info("patrol: %s", line)
