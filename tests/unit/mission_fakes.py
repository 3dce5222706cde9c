"""A scripted robot and scripted algorithms for the mission's unit tests (no Zenoh).

`FakeRobot` implements `RobotPort`: a map of artifacts and people (and an occupancy grid
and floor plan's supports for the patrol), a navigation that finishes a goal after
`nav_ticks` ticks (or fails it, as scripted per goal kind; a pose goal leaves the robot
at the pose; `nav_refuse` refuses chosen goals; with `moves`, the mission's own cmd_vel
moves it), a whole-body controller whose modes
take effect on the next tick and whose arm goals finish after `arm_ticks` (or fail, as
scripted per kind), a grasp detector that holds after a Grasp and can be made to let go
while carrying, and a wrist camera that sees the artifacts listed in `visible`.
Everything the tree (or the patrol) asked for is recorded.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal, cast

import msgspec
import numpy as np
from numpy.typing import NDArray

from common.config import MissionSettings
from common.geometry import make_T
from common.messages import to_wire
from common.messages.navigation import (
    ArtifactStandoff,
    NavFailure,
    NavGoal,
    NavState,
    NavStatus,
    PersonHandover,
    PoseGoal,
    ScanBody,
)
from common.messages.perception import Detection
from common.messages.semantic_map import MapEntity, OccupancyGrid
from common.messages.wbc import (
    ArmGoal,
    GoalState,
    GoalStatus,
    Grasp,
    Reach,
    Release,
    WbcModeName,
    WbcStatus,
)
from common.messages.world import SupportSurface
from common.robot import HANDOVER_DISTANCE_M
from services.mission.algorithms import Algorithms
from services.mission.behaviours.base import Context
from services.mission.person_search import IN_VIEW_RAD
from services.mission.ports import Refused, Unavailable, WristSighting
from services.mission.robot import within_caps

TICK_NS = 50_000_000
#: Navigation fails a goal whose map has not come in 30 s (`navigation.intake.MAP_WAIT_S`).
NAV_MAP_WAIT_TICKS = 600


def entity(map_id: str, x: float, y: float, kind: str = "artifact", yaw: float = 0.0) -> MapEntity:
    """A mapped entity (yaw 0: a person whose facing the map does not know)."""
    return MapEntity(
        id=map_id,
        class_name=map_id.rsplit("_", 1)[0],
        kind=kind,  # type: ignore[arg-type]
        position_in_world=(x, y, 0.8 if kind == "artifact" else 0.0),
        uncertainty_m=0.05,
        last_seen_ns=0,
        source="seed-from-world",
        yaw=yaw,
    )


def detection(map_id: str, d_obj: float = 0.6) -> Detection:
    return Detection(
        class_name=map_id.rsplit("_", 1)[0],
        score=0.9,
        bbox=(0, 0, 2, 2),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=(d_obj, 0.0, 0.8),
        centroid_in_world=(d_obj, 0.0, 0.8),
        axis_in_world=(d_obj, 0.0, 0.8),
        extent=(0.07, 0.07, 0.2),
        d_obj=d_obj,
        theta_obj=0.0,
        n_points=100,
        map_id=map_id,
        shape="cylinder",
    )


@dataclass
class FakeRobot:
    artifacts: dict[str, MapEntity] = field(default_factory=dict)
    people_: dict[str, MapEntity] = field(default_factory=dict)
    visible: set[str] = field(default_factory=set)
    xy: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.0
    #: The person's mapped place moves this far (m, +y) once the robot first stands at
    #: the handover pose.
    person_shift_m: float = 0.0
    #: The person walked here (x, y) before the robot came: at the handover pose the map
    #: does not see them; once the robot has turned `seen_after_turn_rad` on the spot (by
    #: its own cmd_vel or by navigation's pose goals) it sees them there. None: seen where
    #: they are whenever the robot stands facing them.
    person_walked_to: tuple[float, float] | None = None
    seen_after_turn_rad: float = math.pi / 2
    #: ...or once the robot stands within this of where they walked (None: never so).
    sees_within_m: float | None = None
    #: ...or once a turn on the spot ends facing where they walked (within the head
    #: camera's view, `person_search.IN_VIEW_RAD`).
    sees_facing: bool = False
    #: The jaw's angle (rad) where each grasp that holds stops it, in turn (none left:
    #: as the last); the status says `jaw_angle`.
    jaw_angles: list[float] = field(default_factory=list)
    jaw_angle: float = 0.0
    #: The lidars' bodies near the robot (`NavStatus.bodies`).
    bodies_: list[ScanBody] = field(default_factory=list)
    _turned: float = 0.0
    _facing: str = ""
    #: Where each wrist_detection call looked for the target (its mapped place or None).
    looked_near: list[tuple[float, float] | None] = field(default_factory=list)
    nav_ticks: int = 3
    arm_ticks: int = 2
    #: Goal kind (`artifact_standoff`, `person_handover`, `pose`) → "refuse" or a NavFailure.
    nav_fail: dict[str, str] = field(default_factory=dict)
    #: ...for only the first this many goals of each kind (None: every one).
    nav_fail_times: int | None = None
    #: Goal kinds navigation keeps active without moving the base (a person beside it).
    nav_hold: set[str] = field(default_factory=set)
    #: Ticks after a goal is sent before its first status comes (none meanwhile).
    status_lag: int = 0
    _nav_failed: dict[str, int] = field(default_factory=dict)
    #: Goals navigation refuses (no typed code: this goal only), when given.
    nav_refuse: Callable[[NavGoal], bool] | None = None
    #: The map's occupancy grid (None: 8 × 8 m of free floor about the origin) and the
    #: floor plan's supports.
    grid: OccupancyGrid | None = None
    supports: list[SupportSurface] = field(default_factory=list)
    #: Arm goal kind (`posture`, `reach`, `grasp`, `release`) → "refuse" or a reason.
    arm_fail: dict[str, str] = field(default_factory=dict)
    #: Grasps that close on nothing before one holds.
    grasp_misses: int = 0
    #: Grasps that succeed but do not hold (the object slips as the jaw settles).
    slips: int = 0
    #: Reaches made holding the object (the lift) that end short of their goal.
    lift_fails: int = 0
    #: How far from its goal a reach failed by `arm_fail` gives up, m.
    reach_miss_m: float = 0.02
    #: Times the grasp lets go while carrying (after `drop_after` ticks of the handover goal).
    drops: int = 0
    #: The goal kind during which a drop happens (`drops`, after `drop_after` ticks).
    drop_on: str = "person_handover"
    drop_after: int = 1
    #: A drop takes the object out of the wrist camera's sight (it rolled away).
    drop_hides: bool = False
    #: Ticks the first goal waits for navigation's map (taken, `active`, not moving); a
    #: goal that waits `NAV_MAP_WAIT_TICKS` fails `timeout`, as navigation's does.
    nav_not_ready: int = 0
    modes_work: bool = True
    map_up: bool = True
    #: Whether the mission's own cmd_vel moves the robot (in mode walk obeying `mission`).
    moves: bool = False
    #: The map's grid as the robot's sensing made it so far (None: `grid`).
    occupancy_of: Callable[[FakeRobot], OccupancyGrid] | None = None
    t: int = 0
    # what the tree did
    nav_goals: list[tuple[str, NavGoal]] = field(default_factory=list)
    nav_cancels: list[str] = field(default_factory=list)
    arm_goals: list[tuple[str, ArmGoal]] = field(default_factory=list)
    modes: list[tuple[WbcModeName, str]] = field(default_factory=list)
    cmds: list[tuple[float, float, float]] = field(default_factory=list)
    arm_holds: int = 0
    held: bool = False
    #: Navigation's people caps (ahead, behind, left, right; None: none) and their person.
    caps_mps: tuple[float, float, float, float] | None = None
    cap_person: str = ""
    mode: WbcModeName = "stand"
    source: str = "navigation"
    _cmd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _nav: dict[str, tuple[int, str, str]] = field(default_factory=dict)
    _nav_sent: dict[str, int] = field(default_factory=dict)
    _arm: dict[str, tuple[int, ArmGoal]] = field(default_factory=dict)
    _arm_state: dict[str, GoalStatus] = field(default_factory=dict)
    _pending_mode: tuple[WbcModeName, str] | None = None

    # -- the test's clock -----------------------------------------------------------------

    def advance(self) -> None:
        """End of a tick: the commanded cmd_vel is recorded, time moves on, modes apply."""
        self.cmds.append(self._cmd)
        if self.moves and (self.mode, self.source) == ("walk", "mission"):
            vx, vy, wz = self._cmd
            dt = TICK_NS / 1e9
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            self.xy = (self.xy[0] + (c * vx - s * vy) * dt, self.xy[1] + (s * vx + c * vy) * dt)
            self.yaw = math.remainder(self.yaw + wz * dt, math.tau)
            self._turned += abs(wz) * dt
            if self._turned >= self.seen_after_turn_rad:
                self._see_walked_off()
        self._cmd = (0.0, 0.0, 0.0)
        self.t += TICK_NS
        if self._pending_mode is not None and self.modes_work:
            self.mode, self.source = self._pending_mode
            self._pending_mode = None
        for goal_id, (start, goal) in list(self._arm.items()):
            if (
                self._arm_state[goal_id].state == "active"
                and self.t - start >= self.arm_ticks * TICK_NS
            ):
                self._finish_arm(goal_id, goal)
        carrying = [
            g for g, (_, k, state) in self._nav.items() if k == self.drop_on and state == "active"
        ]
        if self.drops > 0 and self.held and carrying:
            start = self._nav[carrying[-1]][0]
            if self.t - start >= self.drop_after * TICK_NS:
                self.held = False
                self.drops -= 1
                if self.drop_hides:
                    self.visible = set()

    @property
    def now_ns(self) -> int:
        return self.t

    # -- map ------------------------------------------------------------------------------

    def _map(self) -> None:
        if not self.map_up:
            raise Unavailable("dume/map/artifacts: no queryable answered")

    def artifact(self, map_id: str) -> MapEntity | None:
        self._map()
        return self.artifacts.get(map_id)

    def artifacts_of_class(self, class_name: str) -> list[MapEntity]:
        self._map()
        return [e for e in self.artifacts.values() if e.class_name == class_name]

    def mapped_artifacts(self) -> list[MapEntity]:
        self._map()
        return [e for e in self.artifacts.values() if e.missing_since_ns is None]

    def person(self, person_id: str) -> MapEntity | None:
        self._map()
        p = self.people_.get(person_id)
        if p is not None and person_id == self._facing and self.person_walked_to is None:
            return msgspec.structs.replace(p, last_seen_ns=self.t)  # seen now
        return p

    def people(self) -> list[MapEntity]:
        self._map()
        return list(self.people_.values())

    def occupancy(self) -> OccupancyGrid:
        self._map()
        if self.occupancy_of is not None:
            return self.occupancy_of(self)
        if self.grid is not None:
            return self.grid
        cells = np.zeros((80, 80), np.uint8)
        return OccupancyGrid(
            stamp_ns=self.t, resolution_m=0.1, origin_xy=(-4.0, -4.0), cells=to_wire(cells)
        )

    def floor_supports(self) -> list[SupportSurface]:
        self._map()
        return list(self.supports)

    def robot_xy(self) -> tuple[float, float] | None:
        return self.xy

    def robot_yaw(self) -> float | None:
        return self.yaw

    # -- navigation -----------------------------------------------------------------------

    def send_nav_goal(self, goal: NavGoal) -> str:
        kind = (
            "artifact_standoff"
            if isinstance(goal, ArtifactStandoff)
            else "person_handover"
            if isinstance(goal, PersonHandover)
            else "pose"
        )
        if self.nav_fail.get(kind) == "refuse" or (self.nav_refuse and self.nav_refuse(goal)):
            raise Refused("invalid_goal: scripted refusal")
        goal_id = f"nav_{len(self.nav_goals) + 1}"
        self.nav_goals.append((goal_id, goal))
        self._nav[goal_id] = (self.t + self.nav_not_ready * TICK_NS, kind, "active")
        self._nav_sent[goal_id] = self.t
        self.nav_not_ready = 0
        return goal_id

    def nav_status(self, goal_id: str) -> NavStatus | None:
        if goal_id not in self._nav or self.t < self._nav_sent[goal_id] + self.status_lag * TICK_NS:
            return None
        start, kind, state = self._nav[goal_id]
        waited = self.t - self._nav_sent[goal_id]
        if state == "active" and self.t < start:  # waiting for the map
            if waited < NAV_MAP_WAIT_TICKS * TICK_NS:
                return NavStatus(
                    stamp_ns=self.t, goal_id=goal_id, state="active", detail="waiting for the map"
                )
            self._nav[goal_id] = (start, kind, "failed")
            return NavStatus(
                stamp_ns=self.t,
                goal_id=goal_id,
                state="failed",
                reason="timeout",
                detail="no map from semantic map within 30 s",
            )
        if state == "failed" and self.t < start:
            return NavStatus(stamp_ns=self.t, goal_id=goal_id, state="failed", reason="timeout")
        if state == "active" and kind in self.nav_hold:
            return NavStatus(stamp_ns=self.t, goal_id=goal_id, state="active",
                             detail="waiting for person_7 to pass")  # fmt: skip
        if state == "active" and self.t - start >= self.nav_ticks * TICK_NS:
            failure = self.nav_fail.get(kind, "")
            if failure and self.nav_fail_times is not None:
                if self._nav_failed.get(kind, 0) >= self.nav_fail_times:
                    failure = ""
                self._nav_failed[kind] = self._nav_failed.get(kind, 0) + 1
            state = "failed" if failure else "succeeded"
            self._nav[goal_id] = (start, kind, state)
            if state == "succeeded" and kind == "person_handover":
                self._arrive_at_person(goal_id)
            if state == "succeeded" and kind == "pose":
                pose = next(g for i, g in self.nav_goals if i == goal_id)
                assert isinstance(pose, PoseGoal)
                if math.dist(self.xy, (pose.x, pose.y)) < 0.05:  # a turn on the spot
                    self._turned += abs(math.remainder(pose.yaw - self.yaw, math.tau))
                self.xy, self.yaw = (pose.x, pose.y), pose.yaw
                if self._turned >= self.seen_after_turn_rad:
                    self._see_walked_off()
                there, within = self.person_walked_to, self.sees_within_m
                if there is not None and within is not None and math.dist(self.xy, there) <= within:
                    self._see_walked_off()
                if there is not None and self.sees_facing:
                    bearing = math.atan2(there[1] - self.xy[1], there[0] - self.xy[0])
                    if abs(math.remainder(bearing - self.yaw, math.tau)) <= IN_VIEW_RAD:
                        self._see_walked_off()
        reason = self.nav_fail.get(kind, "") if state == "failed" else ""
        progress = min(1.0, (self.t - start) / (self.nav_ticks * TICK_NS))
        return NavStatus(
            stamp_ns=self.t,
            goal_id=goal_id,
            state=cast(NavState, state),
            reason=cast(NavFailure, reason),
            progress=progress,
        )

    def _see_walked_off(self) -> None:
        """The person who walked off is seen where they went: the map has them there."""
        if self.person_walked_to is None:
            return
        for pid, p in self.people_.items():
            x, y = self.person_walked_to
            self.people_[pid] = msgspec.structs.replace(
                p, position_in_world=(x, y, 0.0), last_seen_ns=self.t
            )
        self.person_walked_to = None

    def _arrive_at_person(self, goal_id: str) -> None:
        """Stand facing +x at the handover distance (and the goal's `extra_m`) from the
        person's mapped place, as navigation would; then, once, the map moves the person
        by `person_shift_m` (seen from close by, they were not quite where the map had
        them)."""
        goal = next(g for i, g in self.nav_goals if i == goal_id)
        assert isinstance(goal, PersonHandover)
        p = self.people_[goal.person_id].position_in_world
        self.xy, self.yaw = (p[0] - HANDOVER_DISTANCE_M - goal.extra_m, p[1]), 0.0
        self._facing = goal.person_id  # the head camera sees them from close by, if there
        if self.person_shift_m:
            moved = (p[0], p[1] + self.person_shift_m, p[2])
            self.people_[goal.person_id] = msgspec.structs.replace(
                self.people_[goal.person_id], position_in_world=moved
            )
            self.person_shift_m = 0.0

    def cancel_nav(self, goal_id: str, reason: str) -> None:
        self.nav_cancels.append(goal_id)
        for g, (start, kind, state) in self._nav.items():
            if state == "active" and goal_id in ("", g):
                self._nav[g] = (start, kind, "cancelled")

    def bodies(self) -> list[ScanBody]:
        return list(self.bodies_)

    def active_nav_goals(self) -> list[str]:
        return [g for g, (_, _, state) in self._nav.items() if state == "active"]

    # -- wbc ------------------------------------------------------------------------------

    def set_mode(self, mode: WbcModeName, cmd_vel_source: str) -> None:
        self.modes.append((mode, cmd_vel_source))
        self._pending_mode = (mode, cmd_vel_source)

    def command_velocity(self, vx: float, vy: float, wz: float) -> str:
        self._cmd, held = within_caps((vx, vy, wz), self.caps_mps)
        return self.cap_person if held else ""

    def hold_arm(self, reason: str) -> None:
        self.arm_holds += 1
        for goal_id, status in self._arm_state.items():
            if status.state == "active":
                self._arm_state[goal_id] = GoalStatus(
                    goal_id=goal_id, kind=status.kind, state="cancelled", reason=reason
                )

    def send_arm_goal(self, goal: ArmGoal) -> str:
        kind = type(goal).__name__.lower()
        if self.arm_fail.get(kind) == "refuse":
            raise Refused(f"busy: scripted refusal of {kind}")
        if isinstance(goal, Reach) and self.mode != "manipulate":
            raise Refused(f"busy: mode {self.mode}: a reach needs mode manipulate")
        goal_id = f"arm_{len(self.arm_goals) + 1}"
        for g, status in self._arm_state.items():
            if status.state == "active":
                self._arm_state[g] = GoalStatus(goal_id=g, kind=status.kind, state="cancelled")
        self.arm_goals.append((goal_id, goal))
        self._arm[goal_id] = (self.t, goal)
        self._arm_state[goal_id] = GoalStatus(goal_id=goal_id, kind=kind, state="active")
        return goal_id

    def _finish_arm(self, goal_id: str, goal: ArmGoal) -> None:
        kind = type(goal).__name__.lower()
        state, reason, miss = "succeeded", "", 0.0
        if kind in self.arm_fail:
            state, reason = "failed", self.arm_fail[kind]
            miss = self.reach_miss_m if isinstance(goal, Reach) else 0.0
        elif isinstance(goal, Reach) and self.held and self.lift_fails > 0:
            self.lift_fails -= 1
            state, reason = "failed", "gripper_tcp 5.8 cm from the goal"
        elif isinstance(goal, Grasp):
            if self.grasp_misses > 0:
                self.grasp_misses -= 1
                state, reason = "failed", "the jaw closed on nothing"
            elif self.slips > 0:
                self.slips -= 1
            else:
                self.held = True
                if self.jaw_angles:  # where this grasp's jaw stopped
                    self.jaw_angle = self.jaw_angles.pop(0)
        elif isinstance(goal, Release):
            self.held = False
        self._arm_state[goal_id] = GoalStatus(
            goal_id=goal_id, kind=kind, state=cast(GoalState, state), reason=reason, miss_m=miss
        )

    def arm_goal(self, goal_id: str) -> GoalStatus | None:
        return self._arm_state.get(goal_id)

    def wbc_status(self) -> WbcStatus | None:
        return WbcStatus(
            stamp_ns=self.t,
            mode=self.mode,
            cmd_vel_source=self.source,
            goals=list(self._arm_state.values()),
            base_error_m=0.0,
            gripper_error_m=0.0,
            gripper_error_rad=0.0,
            qp_time_us=0.0,
            qp_failures=0,
            contacts=(True, True, True, True),
            gripper_angle=self.jaw_angle,
            gripper_effort=0.0,
            held=self.held,
            gripper_wrench=(0.0,) * 6,
        )

    # -- perception -----------------------------------------------------------------------

    def wrist_detection(
        self,
        map_id: str,
        class_name: str,
        near_xy: tuple[float, float] | None = None,
        any_class: bool = False,
    ) -> WristSighting | None:
        self.looked_near.append(near_xy)
        if map_id in self.visible:
            return WristSighting(self.t, detection(map_id), tuple(np.eye(4).ravel().tolist()))
        return None

    # -- what the tests look at -----------------------------------------------------------

    def arm_kinds(self) -> list[str]:
        return [getattr(g, "name", type(g).__name__.lower()) for _, g in self.arm_goals]


@dataclass
class StubCommand:
    vx: float
    vy: float
    wz: float
    state: str
    reason: str = ""


class StubApproach:
    """Arrives after 3 sightings; fails after 5 ticks without one (its re-acquire)."""

    def __init__(self) -> None:
        self.reset(0.0)

    def reset(self, t_s: float) -> None:
        self.seen = self.lost = 0
        self.held_s, self._held_at = 0.0, -math.inf

    def hold(self, t_s: float) -> None:
        """Held back (navigation's people caps): no nearer, so no arrival yet; the time
        held counted as the real controller counts it."""
        self.seen = min(self.seen, 1)
        if 0.0 < t_s - self._held_at <= 0.5:
            self.held_s += t_s - self._held_at
        self._held_at = t_s

    def step(self, t_s: float, seen: object | None) -> StubCommand:
        if seen is None:
            self.lost += 1
            if self.lost > 5:
                return StubCommand(0.0, 0.0, 0.0, "failed", "lost the object after turning")
            return StubCommand(-0.1, 0.0, 0.5, "reacquiring")
        self.seen += 1
        if self.seen >= 3:
            return StubCommand(0.0, 0.0, 0.0, "arrived")
        return StubCommand(0.2, 0.0, 0.0, "tracking")


class StubGraspError(Exception):
    def __init__(self, reason: str, stance_yaw_rad: float | None = None) -> None:
        super().__init__(reason)
        self.stance_yaw_rad = stance_yaw_rad


@dataclass
class StubPlan:
    kind: str = "side"
    frame: Literal["base", "world"] = "world"
    possible: bool = True
    pregrasp_m: float = 0.08
    close_in_m: float = 0.0
    beyond_m: float = 0.0
    radius_m: float = 0.0
    seat_x_m: float = 0.0
    #: How far deeper it was re-seated (`reseated`), m.
    deeper_m: float = 0.0
    #: The grasp pose in the world: the jaw closes 3 m ahead, where bottle_1 stands.
    H: NDArray[np.float64] = field(default_factory=lambda: make_T(np.eye(3), (3.0, 0.0, 0.8)))

    def reach(self) -> Reach:
        H = np.eye(4)
        H[:3, 3] = (0.0, 0.0, -self.close_in_m)  # the close-in moves it back to 0
        return Reach(
            H=tuple(H.ravel().tolist()), frame=self.frame, stamp_ns=0, pregrasp_m=self.pregrasp_m
        )

    def closed_in(self) -> StubPlan:
        return StubPlan(self.kind, self.frame, self.possible, 0.0)

    def lifted(self, dz_m: float) -> StubPlan:
        return StubPlan(self.kind, self.frame, self.possible, 0.0)

    def backed_out(self) -> StubPlan:
        return StubPlan(self.kind, self.frame, self.possible, 0.0)

    def over_the_spot(self, dz_m: float) -> StubPlan:
        return StubPlan(self.kind, self.frame, self.possible, self.pregrasp_m)

    def reseated(self, deeper_m: float) -> StubPlan:
        return replace(self, deeper_m=deeper_m, close_in_m=0.008)

    def pulled_back(self, dz_m: float, back_m: float, heading_rad: float) -> StubPlan:
        return StubPlan(self.kind, self.frame, self.possible, 0.0)


class StubPull:
    """A pull begins on the first status after the baseline and is felt on the third
    (never either, when `never`)."""

    def __init__(self, never: bool = False) -> None:
        self.never, self.count = never, 0
        self.pull_n = self.across_n = self.effort_change_nm = self.swing_n = 0.0
        self.rising_since_ns: int | None = None

    def note(self, status: WbcStatus) -> None:
        pass

    def reset(self, status: WbcStatus) -> None:
        self.count = 0

    def update(self, status: WbcStatus) -> bool:
        self.count += 1
        return not self.never and self.count >= 3

    def pulled_within(self, t_ns: int, window_s: float) -> bool:
        return not self.never and self.count >= 1


def stub_algorithms(
    grasp_possible: bool = True,
    pull: bool = True,
    pull_on_try: int = 1,
    grasp_plans: int = -1,
    close_in_mm: int = 0,
    stance_plans: int = 0,
    beyond_mm: int = 0,
    grasp_z_mm: int = 800,
    radius_mm: int = 0,
) -> Algorithms:
    """`grasp_plans`: how many grasps are planned before none is possible (−1: all);
    `close_in_mm`: the plans' close-in move (a top grasp's); `stance_plans`: how many
    grasps first ask for another stance (a tall box's long faces off the line of
    sight, along 90°); `beyond_mm`: how far the object reaches past the gripper;
    `grasp_z_mm`: the grasp pose's height over the floor (0.8 m: a bottle's middle on a
    0.7 m table); `radius_mm`: a side-grasped cylinder's radius (0: not one), its seat
    planned 1 cm deeper than its axis."""
    stances = itertools.count(1)
    tries = itertools.count(1)  # the detectors made: one per offer
    plans = itertools.count(1)

    def grasp(det: Detection, stamp_ns: int, T_world_base: object) -> StubPlan:
        if not grasp_possible:
            raise StubGraspError("the object lies on its side")
        if next(stances) <= stance_plans:
            raise StubGraspError("the box's long faces are 60° off", math.pi / 2)
        if 0 <= grasp_plans < next(plans):
            raise StubGraspError("the bottle's side grasp is out of the arm's reach")
        H = make_T(np.eye(3), (3.0, 0.0, grasp_z_mm / 1000))
        seat = -0.01 if radius_mm else 0.0
        return StubPlan(close_in_m=close_in_mm / 1000, beyond_m=beyond_mm / 1000, H=H,
                        radius_m=radius_mm / 1000, seat_x_m=seat)  # fmt: skip

    return Algorithms(
        approacher=StubApproach,
        sighting=lambda d, th, s: (d, th, s),
        grasp_from_detection=grasp,
        grasp_error=StubGraspError,
        pull_detector=lambda: StubPull(never=not pull or next(tries) < pull_on_try),
    )


def fast_settings(**overrides: float) -> MissionSettings:
    """Short timeouts so a scripted mission ends in a few hundred ticks."""
    base = dict(
        settle_s=0.1,
        detection_timeout_s=0.5,
        mode_timeout_s=1.0,
        posture_timeout_s=2.0,
        reach_timeout_s=2.0,
        grasp_timeout_s=2.0,
        release_timeout_s=2.0,
        handover_timeout_s=3.0,
        approach_timeout_s=5.0,
        nav_status_timeout_s=1.0,
        handover_check_s=0.1,
        back_off_s=0.2,
    )
    base.update(overrides)
    return MissionSettings(**base)  # type: ignore[arg-type]


def small_world(**kwargs: object) -> FakeRobot:
    robot = FakeRobot(**kwargs)  # type: ignore[arg-type]
    if not robot.artifacts:
        robot.artifacts = {"bottle_1": entity("bottle_1", 3.0, 0.0)}
    if not robot.people_:
        # facing the robot's way in: as seeded from truth (`unknown_facing` for the search)
        robot.people_ = {"person_1": entity("person_1", -3.0, 1.0, kind="person", yaw=math.pi)}
    if not robot.visible:
        robot.visible = set(robot.artifacts)
    return robot


def context(robot: FakeRobot, settings: MissionSettings | None = None, **alg: int) -> Context:
    decisions: list[str] = []
    ctx = Context(robot, settings or fast_settings(), stub_algorithms(**alg), decisions.append)
    ctx.decisions = decisions  # type: ignore[attr-defined]
    return ctx


def is_handover(goal: NavGoal) -> bool:
    return isinstance(goal, PersonHandover)
