"""The leaves that move the base: the wbc mode, navigation goals, the back-off.

- `SetMode(mode, source)`: asks the whole-body controller for a mode and the cmd_vel
  source it obeys; succeeds once `wbc/status` reports both (modes take effect one
  mission latency after their stamp), fails `mode_timeout` after `mode_timeout_s`.
- `NavigateTo("artifact" | "person" | "put_back")`: sends `ArtifactStandoff(target)`
  (at an end of the line of sight a grasp asked for, `STANCE`, when it did),
  `PersonHandover(person)` (or, while looking for them, a `PoseGoal` to one of their
  usual places) or a `PoseGoal` to where the base stood to pick the object it
  still holds (`Held.stance`, within `PUT_BACK_TOL_M`/`_RAD`: the arm puts it down at
  the grasp's own pose) on start and watches `nav/status` for that goal id; a refusal
  or a failed goal fails `navigation_failed` with navigation's reason (the goal is sent
  once: navigation takes one sent before its first map and waits for the map). A walk
  that carries the object is watched by `carrying.WhileHeld` (`grasp_lost`). Walking
  to a person whose map entry is stale while somebody stands near in their colours
  (`identity.wearer_near`, checked once a second), it walks to that one (`PERSON`), said,
  with a new goal; not when more than one in the map wears them (said once). Preempted
  (or failing while the goal is active) it cancels its goal. An object that fell from
  the gripper (`Target.dropped`) lies by the robot's feet, out of its cameras' view: it
  steps back to look at the floor there (`look_where_it_fell`; failing that, or where it
  fell unknown, it looks from where it stands).
- `PersonAhead`: at the handover pose, stand `handover_check_s` (the head camera's
  fresh sightings of the person reach the map), then check that the map saw the person
  meanwhile and that their latest mapped place is `HANDOVER_DISTANCE_M` straight ahead
  within `handover_tol_m`; when not, FAILURE, a condition (no mission failure): the tree
  walks to the person again, after looking round for them when they were not seen
  (`UNSEEN`; not a person the map saw walking on within `PERSON_FRESH_S`, nor, once
  somebody else stood at the handover, `identity.RightPerson`, one the map has farther
  than `PERSON_HERE_M`: the tree walks to where the map has them). The map
  can hold a person some tenths of a metre off until it sees them from close by, and the
  person's hand takes only what is held out within 0.25 m of it.
- `SeenThere`: SUCCESS unless the person was not seen at their place (`UNSEEN`).
- `LookForPerson`: the person was not where the map had them. Turn on the spot once
  round (`LOOK_TURNS` pose goals to navigation, as the patrol's look-around: its body
  guard keeps the body's ends off what stands round, its people rules hold the turn for
  a person near; before, the mission turned the base with its own cmd_vel and swept the
  hips into a pallet, 9 contacts in one shift; not where it looked round already in this
  request) while the head camera sweeps the floor round it, asking the map each tick
  whether it saw them since the look began; then stand `person_ask_s` asking for them
  ("asking for <person>: please come to the robot"), turning the head camera to each
  body the lidars track near that it does not see and the map cannot name
  (`person_search.glance_at`: a walker passing behind it; the ask waits for a turn under
  way, and the camera looks `GLANCE_LOOK_S` once there). A person who comes while it
  asks and stands within `ANSWER_M` of the base for `ANSWER_STAND_S` (not one who stood
  that near already when it began to ask, nor a walker pausing in its way: they walk on
  within 4 s; nor while the camera turns to a body the lidars track: hall seed 11's
  shift took a bystander who had stood 1.9 m off for 5 s while it turned to the worker
  asked for, 1.1 m behind it, and handed them the bottle) answered (one who came before
  the ask's end is waited for past it, while they stand there: hall seed 4's shift gave
  up asking 4 s after the worker asked for had come and stood 1.7 m off, and looked for
  them 80 s more): the map's id for them may be another one (the map lost who is who
  while they walked: hall seed 1's shift saw the requested person as three new ids while
  the robot looked for the old one, and the request timed out), and the fetch goes on to
  them under that id (`PERSON`), said. Seen: SUCCESS, and the walk to them goes to where
  they were seen; never seen: SUCCESS all the same, and the next walk goes to the next
  of their usual places (`LOOK_AT`, `person_search.next_place`: where the map saw them
  most), or, none left, to where the map last had them. A walk to a usual place
  (`NavigateTo`, a `PoseGoal` within `LOOK_AT_TOL_M`, any heading) ends as soon as the
  map sees the person.
- `StandsThere`: after one more walk to the person, SUCCESS (present) only when the map
  sees them standing in front of the robot (`in_front`); else FAILURE
  `person_not_found`, which the tree takes as one more round of looking (`find_person`,
  `person_rounds` in all): the last one's detail says where it looked round and where
  the map last saw them, walking or not.
- `BackOff`: `back_off_speed` backwards for `back_off_s` (or the `distance` it is given:
  the stow's, `stow_room`) on cmd_vel (source mission), or less: only as far as the
  map's grid leaves room behind the footprint (`room_behind`; none without the map or
  the pose).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import numpy as np
from py_trees.common import Status

from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.mission import MissionReason
from common.messages.navigation import ArtifactStandoff, NavGoal, PersonHandover, PoseGoal
from common.messages.semantic_map import MapEntity
from common.messages.wbc import WbcModeName
from common.robot import HANDOVER_DISTANCE_M, floor_view_m
from services.mission.behaviours.base import (
    GRASP_PLAN,
    LOOK_AT,
    LOOKED,
    OTHERS,
    PERSON,
    PERSON_LOOK,
    SIDE,
    STANCE,
    UNSEEN,
    Context,
    MissionBehaviour,
)
from services.mission.behaviours.handover import side_bearing
from services.mission.behaviours.identity import (
    STALE_S,
    Look,
    look_alikes,
    other_clothes,
    said,
    wearer_near,
)
from services.mission.goal_job import LOOK_TURNS, POSITION_TOLERANCE_M, TURN_TOLERANCE_RAD
from services.mission.patrol_goals import PatrolGoal, look_around
from services.mission.person_search import (
    ANSWER_M,
    LOOKED_M,
    WALKING_MPS,
    glance_at,
    next_place,
)
from services.mission.ports import PortError, Refused, Unavailable
from services.mission.room_behind import room_behind

#: A put-back's stance: within this of where the base stood for the grasp (m, rad).
PUT_BACK_TOL_M = 0.05
PUT_BACK_TOL_RAD = 0.08
#: A stance for a grasp along a box's long faces (`STANCE`): the standoff's bearing
#: from the box within this of that line (rad), as far off as the grasp takes them
#: (`GraspParams.box_side_max_off_rad`): hall seed 1's box_2 lies near table_2's corner,
#: and no standoff nearer than 17-22° off its faces is free (20° refused it).
STANCE_TOL_RAD = math.radians(25.0)
#: m: a person's usual place is reached within this (any heading: the robot looks round).
LOOK_AT_TOL_M = 0.5
#: m: the robot stands this short of a person's usual place, on the line from it (`look_at`):
#: where a worker stands at a bench lies in the bench's inflated cells (seed 0's shift:
#: "(-1.62, -0.36) is in an obstacle and no free pose lies within 0.50 m", and the four
#: rounds after it asked at the one place again).
LOOK_FROM_M = 1.0
#: A person seen within this (s) and slower than `person_search.WALKING_MPS` stands where
#: the map has them.
PERSON_FRESH_S = 3.0
#: m: a person this far ahead of the robot's front (about `HANDOVER_DISTANCE_M`) and this
#: far to a side is near enough to present to; elsewhere the walk went to one of their
#: usual places, or navigation stopped short.
PRESENT_AHEAD_M = (HANDOVER_DISTANCE_M - 0.3, HANDOVER_DISTANCE_M + 0.5)
PRESENT_SIDE_M = 0.5
#: m: how far past the gripper's TCP the handover distance lets an object reach (a
#: bottle's far side, 2-3 cm); one that reaches farther is held out from farther away,
#: by the difference, at most `HANDOVER_EXTRA_MAX_M`: hall seed 1's tall box, held by
#: its near end, reached 11 cm out and pressed into the person's forearm (12 N at rest)
#: with the robot 5 cm inside its goal's tolerance, and the person never took it.
HANDOVER_BEYOND_M = 0.03
HANDOVER_EXTRA_MAX_M = 0.3
#: s: a person who comes within `person_search.ANSWER_M` of the base while it asks for
#: someone answered the ask, once they have stood there this long: longer than a walker
#: pauses in the robot's way before turning back (`services.sim.people.GIVE_WAY_S`, 4 s).
ANSWER_STAND_S = 5.0


def ahead_left(
    xy: tuple[float, float], yaw: float, point: tuple[float, float]
) -> tuple[float, float]:
    """A floor point (world) as the robot at (xy, yaw) sees it: metres ahead, to the left."""
    dx, dy = point[0] - xy[0], point[1] - xy[1]
    return math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy


def in_front(
    xy: tuple[float, float] | None, yaw: float | None, person_xy: tuple[float, float]
) -> bool:
    """Whether a person at person_xy is near enough in front of the robot to present to."""
    if xy is None or yaw is None:
        return False
    ahead, left = ahead_left(xy, yaw, person_xy)
    return PRESENT_AHEAD_M[0] <= ahead <= PRESENT_AHEAD_M[1] and abs(left) <= PRESENT_SIDE_M


class SetMode(MissionBehaviour):
    def __init__(
        self, ctx: Context, mode: WbcModeName, source: str, stage: str, name: str = ""
    ) -> None:
        super().__init__(name or f"mode_{mode}_{source}", ctx, stage)
        self.mode, self.source = mode, source

    def initialise(self) -> None:
        super().initialise()
        self.port.set_mode(self.mode, self.source)

    def update(self) -> Status:
        status = self.port.wbc_status()
        if (
            status is not None
            and status.mode == self.mode
            and (self.mode != "walk" or status.cmd_vel_source == self.source)
        ):
            self.feedback_message = f"in {self.mode} ({status.cmd_vel_source})"
            return Status.SUCCESS
        if self.elapsed_s() > self.settings.mode_timeout_s:
            now = "no wbc/status" if status is None else f"{status.mode} ({status.reason})"
            return self.fail(
                "mode_timeout",
                f"the controller is still in {now} {self.elapsed_s():.1f} s after "
                f"{self.mode} from {self.source} was asked for",
            )
        self.feedback_message = f"waiting for mode {self.mode}"
        return Status.RUNNING


class NavigateTo(MissionBehaviour):
    WRITES = (LOOK_AT, PERSON)

    def __init__(
        self,
        ctx: Context,
        kind: Literal["artifact", "person", "put_back"],
        stage: str,
        name: str = "",
        fails_as: tuple[MissionReason, str] | None = None,
    ) -> None:
        super().__init__(name or f"navigate_to_{kind}", ctx, stage)
        self.kind = kind
        #: What its failure is for the request, and what it says first (a walk that is a
        #: means to another end: to a stance for a grasp, `grasp_pose_failed`).
        self.fails_as = fails_as
        self.goal_id = ""
        self.active = False
        self.error: PortError | None = None
        #: Walking to a person's usual place (`LOOK_AT`), not to the person.
        self.to_place = False
        #: When the walk to a person last looked for them under another id (sim ns).
        self.wearer_checked_ns = 0
        #: When the goal walked now was sent (sim ns).
        self.sent_ns = 0
        #: The walk said that colours cannot tell who the person is.
        self.alike_said = False

    def _goal(self) -> NavGoal:
        if self.kind == "put_back":
            held = self.ctx.holding
            if held is None or held.stance is None:
                raise RuntimeError(f"{self.name}: nothing held to put back (tree misbuilt)")
            x, y, yaw = held.stance
            return PoseGoal(x=x, y=y, yaw=yaw, position_tolerance_m=PUT_BACK_TOL_M,
                            yaw_tolerance_rad=PUT_BACK_TOL_RAD)  # fmt: skip
        if self.kind == "artifact":
            target = self.target()
            if target.dropped and target.xy is not None:
                return look_where_it_fell(target.xy, self.port.robot_xy(), self.port.robot_yaw())
            stance = self.get(STANCE)
            if stance is None:
                return ArtifactStandoff(artifact_id=target.map_id)
            ends = (math.remainder(stance + math.pi, math.tau), math.remainder(stance, math.tau))
            return ArtifactStandoff(
                artifact_id=target.map_id, bearings_rad=ends, bearing_tolerance_rad=STANCE_TOL_RAD
            )
        place = self.get(LOOK_AT)
        if place is not None:
            self.to_place = True
            return look_at(place.xy, self.port.robot_xy())
        side = self.get(SIDE)
        return PersonHandover(person_id=str(self.get(PERSON)), bearing_rad=side_bearing(side),
                              extra_m=handover_extra_m(self))  # fmt: skip

    def fail(self, reason: MissionReason, detail: str) -> Status:
        if self.fails_as is None:
            return super().fail(reason, detail)
        return super().fail(self.fails_as[0], f"{self.fails_as[1]}{detail}")

    def _dropped(self) -> bool:
        """The object fell from the gripper near the robot: not walked to at its map place."""
        return self.kind == "artifact" and self.target().dropped

    def initialise(self) -> None:
        super().initialise()
        self.goal_id, self.active, self.error, self.to_place = "", False, None, False
        self.sent_ns, self.alike_said = self.port.now_ns, False
        if self._dropped():
            self.ctx.decide(f"{self.name}: {self.target().map_id} fell "
                            f"{self.target().where_dropped()}: looking for it there")  # fmt: skip
            if self.target().xy is None:
                return  # where is unknown: looked for from here
        self._send()

    def _send(self) -> None:
        goal = self._goal()
        try:
            self.goal_id = self.port.send_nav_goal(goal)
            self.active, self.error, self.sent_ns = True, None, self.port.now_ns
            self.ctx.decide(f"{self.name}: {type(goal).__name__} sent as {self.goal_id}")
        except PortError as exc:
            self.error = exc

    def update(self) -> Status:
        if self.to_place and self._seen_on_the_way():
            return Status.SUCCESS
        if self.kind == "person" and not self.to_place and self.active:
            self._to_wearer()
        status = self._update()
        if status == Status.FAILURE and self._dropped():
            self.ctx.decide(f"{self.name}: no step back to look: looking from here")
            return Status.SUCCESS
        if status != Status.RUNNING and self.to_place:
            self.set(LOOK_AT, None)  # looked at (or not reachable): not walked to again
        return status

    def _seen_on_the_way(self) -> bool:
        """On the way to a person's usual place, the map saw them: the walk ends, and the
        next goes to them."""
        pid, person = the_person(self)
        if person is None or person.last_seen_ns < self.started_ns:
            return False
        if self.active:
            self.port.cancel_nav(self.goal_id, f"{pid} seen")
            self.active = False
        self.set(LOOK_AT, None)
        x, y = person.position_in_world[:2]
        self.ctx.decide(f"{pid} seen at ({x:.2f}, {y:.2f}) on the way to their usual place: "
                        "walking to them")  # fmt: skip
        return True

    def _to_wearer(self) -> None:
        """Once a second: the person asked for stands near the robot under another map
        id (`identity.wearer_near`): the walk goes to them under it."""
        now = self.port.now_ns
        if now - self.wearer_checked_ns < NS_PER_S:
            return
        self.wearer_checked_ns = now
        xy = self.port.robot_xy()
        pid, asked = the_person(self)
        if xy is None:
            return
        try:
            people = self.port.people()
        except PortError:
            return
        look, others = self.get(PERSON_LOOK), self.get(OTHERS) or []
        best = wearer_near(look, asked, people, xy, now, _standing(now), others)
        if best is None:
            self._say_alike(look, asked, people, others)
            return
        who, bands = best
        age = "gone from the map" if asked is None else (
            f"not seen for {(now - asked.last_seen_ns) / NS_PER_S:.0f} s")  # fmt: skip
        self.ctx.decide(f"{pid} {age}; {who.id}, standing "
                        f"{math.dist(who.position_in_world[:2], xy):.1f} m from the robot, "
                        f"wears their colours ({said(bands)}): walking to {who.id}")  # fmt: skip
        self.set(PERSON, who.id)
        self.port.cancel_nav(self.goal_id, f"{pid} is {who.id}")
        self._send()

    def _say_alike(
        self, look: Look | None, asked: MapEntity | None, people: list[MapEntity], others: list[str]
    ) -> None:
        """Once a walk: the entry asked for is stale and more than one in the map wears
        their colours (`identity.look_alikes`), so colours cannot say who stands near."""
        if self.alike_said or look is None or asked is None:
            return
        unseen_s = (self.port.now_ns - asked.last_seen_ns) / NS_PER_S
        alike = look_alikes(look, people, [*others, asked.id])
        if unseen_s < STALE_S or len(alike) < 2:
            return
        self.alike_said = True
        ids = ", ".join(f"{q.id} ({said(b)})" for q, b in alike)
        self.ctx.decide(f"{asked.id} not seen for {unseen_s:.0f} s; "
                        f"{ids} wear their colours: colours cannot say who, walking on to "
                        f"where {asked.id} was seen")  # fmt: skip

    def _update(self) -> Status:
        if self._dropped() and not self.goal_id and self.error is None:
            self.feedback_message = "where it fell"
            return Status.SUCCESS
        if self.error is not None:
            reason: MissionReason = (
                "navigation_failed" if isinstance(self.error, Refused) else "unavailable"
            )
            return self.fail(reason, f"navigation did not take the goal: {self.error}")
        status = self.port.nav_status(self.goal_id)
        if status is None or status.state == "idle":
            # from when this goal was sent: a walk redirected to the person's other id
            # sends a second one late (it failed at once, "no status after 8.0 s")
            waited = (self.port.now_ns - self.sent_ns) / NS_PER_S
            if waited > self.settings.nav_status_timeout_s:
                return self.fail(
                    "navigation_failed", f"no status of goal {self.goal_id} after {waited:.1f} s"
                )
            return Status.RUNNING
        if status.state == "active":
            self.fraction = status.progress
            self.feedback_message = f"{status.remaining_m:.1f} m to go"
            return Status.RUNNING
        self.active = False
        if status.state == "succeeded":
            self.fraction = 1.0
            self.feedback_message = f"goal {self.goal_id} reached"
            return Status.SUCCESS
        why = status.reason or status.state
        return self.fail("navigation_failed", f"goal {self.goal_id} {why}: {status.detail}")

    def terminate(self, new_status: Status) -> None:
        if self.active and new_status != Status.SUCCESS:
            self.port.cancel_nav(self.goal_id, f"{self.name} stopped")
            self.ctx.decide(f"{self.name}: goal {self.goal_id} cancelled")
        self.active = False


def look_where_it_fell(
    at: tuple[float, float], xy: tuple[float, float] | None, yaw: float | None
) -> PoseGoal:
    """The pose from which the wrist camera (arm in `look`) sees the floor where an object
    fell (`common.robot.floor_view_m` short of it, facing it, on the line from the robot;
    the robot's heading when it stands on the spot or its place is unknown): what fell
    at its feet is under the gripper, out of every camera's view."""
    heading = 0.0 if yaw is None else yaw
    if xy is not None and math.hypot(at[0] - xy[0], at[1] - xy[1]) > 0.05:
        heading = math.atan2(at[1] - xy[1], at[0] - xy[0])
    back = floor_view_m()
    return PoseGoal(
        x=at[0] - back * math.cos(heading),
        y=at[1] - back * math.sin(heading),
        yaw=heading,
        position_tolerance_m=0.15,
        yaw_tolerance_rad=0.2,
    )


def look_at(place: tuple[float, float], xy: tuple[float, float] | None) -> PoseGoal:
    """The pose to look round a person's usual place from: `LOOK_FROM_M` short of it on
    the line from the robot (`xy`; None or nearer than that: the place itself), facing
    it, within `LOOK_AT_TOL_M` and any heading."""
    dx, dy = (0.0, 0.0) if xy is None else (place[0] - xy[0], place[1] - xy[1])
    d = math.hypot(dx, dy)
    back = min(LOOK_FROM_M, d) / max(d, 1e-9)  # 0 where the robot's place is unknown
    return PoseGoal(x=place[0] - back * dx, y=place[1] - back * dy, yaw=math.atan2(dy, dx),
                    position_tolerance_m=LOOK_AT_TOL_M, yaw_tolerance_rad=math.pi)  # fmt: skip


def handover_extra_m(b: MissionBehaviour) -> float:
    """How much farther than `HANDOVER_DISTANCE_M` the robot stands to hold out what it
    carries: as far as the object reaches past the gripper beyond what a bottle does
    (`HANDOVER_BEYOND_M`), from the grasp's plan (`GraspPlan.beyond_m`; none known: 0)."""
    plan = b.get(GRASP_PLAN)
    if plan is None and b.ctx.holding is not None:
        plan = b.ctx.holding.plan
    beyond = float(getattr(plan, "beyond_m", 0.0))
    return min(max(0.0, beyond - HANDOVER_BEYOND_M), HANDOVER_EXTRA_MAX_M)


def _standing(now_ns: int) -> Callable[[MapEntity], bool]:
    """Whether the map sees a person standing now: seen within `PERSON_FRESH_S`, slower
    than `WALKING_MPS`."""

    def standing(q: MapEntity) -> bool:
        fresh = now_ns - q.last_seen_ns <= PERSON_FRESH_S * NS_PER_S
        return fresh and math.hypot(*q.velocity_in_world) < WALKING_MPS

    return standing


def the_person(b: MissionBehaviour) -> tuple[str, MapEntity | None]:
    """The requested person's map id and the map's entry for them (None: not in the map,
    or the map did not answer)."""
    pid = str(b.get(PERSON))
    try:
        return pid, b.port.person(pid)
    except Unavailable:
        return pid, None


#: Once somebody else stood at the handover (`identity.RightPerson`), a person mapped
#: farther than this from the base is not looked round for here: the tree walks to where
#: the map has them, m.
PERSON_HERE_M = 2.5


#: The look round for a person is the patrol's look-around (`patrol_goals.look_around`:
#: `LOOK_TURNS` pose goals at the robot's place, within `goal_job`'s tolerances: navigation
#: may move the pose to where the footprint turns clear); it asks after the turns or after
#: `LOOK_TURN_MAX_S`, or as soon as a turn has not turned the base `TURN_PROGRESS_RAD` in
#: `TURN_HELD_S` (the speed rules hold a turn on the spot within a bystander's S_p at
#: rest: hall seed 0's shift stood 40 s at the first turn, person_1 0.65 m off the
#: footprint; the turns after it would be held as long).
LOOK_TURN_MAX_S = 40.0
TURN_HELD_S = 5.0
TURN_PROGRESS_RAD = 0.1
#: s the head camera looks at a body once turned to it (the map names who it sees there).
GLANCE_LOOK_S = 1.0


class PersonAhead(MissionBehaviour):
    WRITES = (UNSEEN,)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("person_ahead", ctx, stage)

    def update(self) -> Status:
        s = self.settings
        if self.elapsed_s() < s.handover_check_s:
            self.feedback_message = "looking at the person"
            return Status.RUNNING
        person_id, person = the_person(self)
        xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
        if person is None or xy is None or yaw is None:
            self.feedback_message = "cannot check: presenting where navigation stopped"
            return Status.SUCCESS
        # after somebody else stood here (`OTHERS`), the person walked to next may be
        # mapped anywhere: looked round for only where the map has them
        here = not self.get(OTHERS) or math.dist(xy, person.position_in_world[:2]) <= PERSON_HERE_M
        # a walker seen walking within PERSON_FRESH_S is walked to, not looked round for
        # where they are not (hall seed 1's shift: seen walking at 1 m/s 1 s before, the
        # robot turned round, asked 20 s and walked to an old usual place of theirs)
        age_s = (self.port.now_ns - person.last_seen_ns) / NS_PER_S
        walking = age_s <= PERSON_FRESH_S and math.hypot(*person.velocity_in_world) >= WALKING_MPS
        unseen = person.last_seen_ns < self.started_ns and not walking
        if unseen and not self.get(UNSEEN) and here:
            self.ctx.decide(
                f"{person_id} not seen at their place in {self.elapsed_s():.1f} s here: "
                "looking round for them"
            )
            self.set(UNSEEN, True)
            return Status.FAILURE
        ahead, left = ahead_left(xy, yaw, person.position_in_world[:2])
        off = math.hypot(ahead - HANDOVER_DISTANCE_M - handover_extra_m(self), left)
        if off <= s.handover_tol_m:
            self.feedback_message = f"{person_id} {off:.2f} m from the handover place"
            return Status.SUCCESS
        self.ctx.decide(
            f"{person_id} is {off:.2f} m from where the handover pose put them "
            f"({ahead:.2f} m ahead, {left:+.2f} m left): walking to them again"
        )
        return Status.FAILURE


class WalkedShort(MissionBehaviour):
    """After the walk to the person failed with `navigation_failed` (their handover pose
    could not be reached: a bystander stood by it, the map had them where nobody stands):
    SUCCESS, the failure forgotten, so that find_person checks whether they are ahead and
    else looks for them, as after a walk that ended (the changing hall's shift: the robot
    stood 0.09 m from the pose of a person who had walked off, a bystander 0.45 m from its
    footprint, for 120 s of navigation's recoveries, and the request failed there with
    the person never looked for). Any other failure (the grasp let go) stays a FAILURE."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("walked_short", ctx, stage)

    def update(self) -> Status:
        failure = self.forget_failure("navigation_failed")
        if failure is None:
            return Status.FAILURE
        self.ctx.decide(f"{failure.behaviour} fell short ({failure.detail}): "
                        "checking whether the person is here, else looking for them")  # fmt: skip
        return Status.SUCCESS


class SeenThere(MissionBehaviour):
    """SUCCESS unless the person was not seen at their mapped place (`UNSEEN`)."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("seen_there", ctx, stage)

    def update(self) -> Status:
        return Status.FAILURE if self.get(UNSEEN) else Status.SUCCESS


class StandsThere(MissionBehaviour):
    """After one more walk to the person: SUCCESS when the map sees them standing (seen
    within `PERSON_FRESH_S`, slower than `WALKING_MPS`) in front of it (`in_front`): the
    robot presents there. Else FAILURE `person_not_found` (they walk on, were not seen,
    or the walk went to one of their usual places), which the tree's find_person takes as
    one more round; its detail, the last, says where the robot looked and where the map
    last saw them."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("stands_there", ctx, stage)

    def update(self) -> Status:
        pid, person = the_person(self)
        looked = ", ".join(f"({x:.1f}, {y:.1f})" for x, y in self.get(LOOKED) or [])
        where = f"looked round at {looked}" if looked else "not looked round for"
        if person is None:
            return self.fail("person_not_found", f"{pid} is not in the map; {where}")
        age = (self.port.now_ns - person.last_seen_ns) / NS_PER_S
        speed = math.hypot(*person.velocity_in_world)
        x, y = person.position_in_world[:2]
        xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
        away = math.inf if xy is None else math.hypot(x - xy[0], y - xy[1])
        if _standing(self.port.now_ns)(person) and in_front(xy, yaw, (x, y)):
            self.feedback_message = f"{pid} stands there"
            return Status.SUCCESS
        walking = f", walking at {speed:.1f} m/s" if speed >= WALKING_MPS else ""
        seen = (
            f"the map last saw them {age:.0f} s ago"
            if person.last_seen_ns > 0
            else "the map has not seen them since it started (a place from its file)"
        )
        return self.fail(
            "person_not_found",
            f"{pid} not reached; {where}; {seen}, now at ({x:.1f}, {y:.1f}), "
            f"{away:.1f} m away{walking}",
        )


class LookForPerson(MissionBehaviour):
    """Turn once round through navigation, then ask, until the map sees the person (the
    module docstring)."""

    WRITES = (UNSEEN, LOOK_AT, LOOKED, PERSON)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("look_for_person", ctx, stage)
        self.turned = 0.0
        self.last_yaw: float | None = None
        self.asked_ns: int | None = None
        #: The people near when the ask began (no answer), and since when each person
        #: who came has stood near (sim ns).
        self.near_at_ask: set[str] = set()
        self.standing: dict[str, int] = {}
        #: The turns still to send and the goal id of the one navigation walks now, and
        #: the yaw it last turned past (rad) and when (sim ns): a turn held still ends.
        self.turns: list[PatrolGoal] = []
        self.goal_id = ""
        self.turn_mark: tuple[float, int] | None = None
        #: The lidar tracks turned to while asking (`glance_at`: id → where), and until
        #: when (sim ns) the camera looks at the last one.
        self.glanced: dict[str, tuple[float, float]] = {}
        self.glance_until_ns = 0

    def initialise(self) -> None:
        super().initialise()
        self.turned, self.last_yaw, self.asked_ns = 0.0, self.port.robot_yaw(), None
        self.turns, self.goal_id, self.turn_mark = [], "", None
        self.near_at_ask, self.standing = set(), {}
        self.glanced, self.glance_until_ns = {}, 0
        xy, yaw = self.port.robot_xy(), self.last_yaw
        if xy is not None and any(math.dist(xy, q) <= LOOKED_M for q in self.get(LOOKED) or []):
            self.turned = math.tau  # looked round here already: only waits and asks
        elif xy is not None and yaw is not None:
            self.turns = look_around(0, xy[0], xy[1], yaw, LOOK_TURNS)[1:]

    def update(self) -> Status:
        pid, person = the_person(self)
        if person is not None and person.last_seen_ns >= self.started_ns:
            x, y = person.position_in_world[:2]
            self.ctx.decide(f"{pid} seen at ({x:.2f}, {y:.2f}) after {self.elapsed_s():.1f} s")
            return self._done()
        yaw = self.port.robot_yaw()
        if yaw is not None and self.last_yaw is not None:
            self.turned += abs(math.remainder(yaw - self.last_yaw, math.tau))
        self.last_yaw = yaw
        if self.asked_ns is None and self._turning(pid):
            self.say = f"looking for {pid}"
            self.fraction = 0.5 * min(self.turned / math.tau, 1.0)
            return Status.RUNNING
        people = self._people()
        if self.asked_ns is None:
            self.asked_ns = self.port.now_ns
            self.near_at_ask = {q.id for q, _ in self._near_people(people)}
            whole = self.turned >= math.tau - TURN_TOLERANCE_RAD
            turn = "a turn" if whole else f"{math.degrees(self.turned):.0f}°"
            self.ctx.decide(f"{pid} not seen in {turn} round their place: asking for them")
        self.say = f"asking for {pid}: please come to the robot"
        waited = (self.port.now_ns - self.asked_ns) / 1e9
        glancing = self._glance(pid, people, waited < self.settings.person_ask_s)
        if self._answer(pid, people, take=not glancing) is not None:
            return self._done()
        if waited < self.settings.person_ask_s or glancing:
            self.fraction = 0.5 + 0.5 * waited / max(self.settings.person_ask_s, 1e-9)
            return Status.RUNNING
        asked_until = self.asked_ns + round(self.settings.person_ask_s * NS_PER_S)
        if any(t < asked_until for t in self.standing.values()):
            return Status.RUNNING  # somebody who came while it asked stands near: waited for
        return self._not_seen(pid, person)

    def _people(self) -> list[MapEntity]:
        """The map's people as of this tick (none when the map does not answer)."""
        try:
            return self.port.people()
        except PortError:
            return []

    def _near_people(self, people: list[MapEntity]) -> list[tuple[MapEntity, float]]:
        """Of `people`, those seen lately (`PERSON_FRESH_S`), standing (slower than
        `WALKING_MPS`), within `ANSWER_M` of the base, with their distance; not one
        clearly in other clothes than the person asked for (`identity.other_clothes`), nor one
        found at the handover in them already (`OTHERS`)."""
        xy = self.port.robot_xy()
        if xy is None:
            return []
        standing = _standing(self.port.now_ns)
        look, others = self.get(PERSON_LOOK), self.get(OTHERS) or []
        out = []
        for q in people:
            d = math.dist(xy, q.position_in_world[:2])
            asked = q.id not in others and not other_clothes(look, q)
            if d <= ANSWER_M and standing(q) and asked:
                out.append((q, d))
        return out

    def _answer(self, pid: str, people: list[MapEntity], take: bool) -> str | None:
        """The id of the person who answered the ask (the module docstring), taken as
        `pid` from now on (`PERSON`); None while nobody has, or while not `take`: the
        camera turns to look at somebody the lidars track (`_glance`), who may be the one
        asked for (who stood near since when is kept meanwhile)."""
        now = self.port.now_ns
        near = {q.id: (q, d) for q, d in self._near_people(people)
                if q.id not in self.near_at_ask}  # fmt: skip
        self.standing = {i: self.standing.get(i, now) for i in near}
        stood = [i for i, t in self.standing.items()
                 if (now - t) / NS_PER_S >= ANSWER_STAND_S]  # fmt: skip
        if not stood or not take:
            return None
        who, (q, d) = min(((i, near[i]) for i in stood), key=lambda item: item[1][1])
        if who != pid:
            self.set(PERSON, who)
        x, y = q.position_in_world[:2]
        self.ctx.decide(f"{who} came while the robot asked for {pid} and stands {d:.1f} m "
                        f"from it at ({x:.2f}, {y:.2f}): taken as {pid}, the handover goes "
                        f"to {who}")  # fmt: skip
        return who

    def _turning(self, pid: str) -> bool:
        """Whether a turn is under way: the next turn sent once the last ended (a failed
        one passed over, as the patrol's); False once none is left, navigation refused,
        or `LOOK_TURN_MAX_S` went by (a base held still for a person beside it)."""
        if self.elapsed_s() >= LOOK_TURN_MAX_S:
            self._cancel(f"the look round for {pid} took {LOOK_TURN_MAX_S:.0f} s")
            return False
        if self.goal_id:
            status = self.port.nav_status(self.goal_id)
            if status is None or status.state in ("idle", "active"):
                return not self._held(pid)
            if status.state != "succeeded":
                why = status.reason or status.state
                self.ctx.decide(f"look_for_person: turn {self.goal_id} {why} ({status.detail}): "
                                "passed over")  # fmt: skip
            self.goal_id = ""
        if not self.turns:
            return False
        turn = self.turns.pop(0)
        try:
            self._turn_to(turn.x, turn.y, turn.yaw)
        except PortError as exc:
            self.ctx.decide(f"look_for_person: navigation did not take the turn ({exc}): "
                            "looking from here")  # fmt: skip
            self.turns = []
            return False
        k = LOOK_TURNS - len(self.turns)
        self.ctx.decide(f"look_for_person: turn {k}/{LOOK_TURNS} to {math.degrees(turn.yaw):.0f}° "
                        f"sent as {self.goal_id}")  # fmt: skip
        return True

    def _turn_to(self, x: float, y: float, yaw: float) -> None:
        """Send navigation a turn on the spot at (x, y) to `yaw` (`PortError` when it does
        not take it); its progress is watched afresh (`_held`)."""
        goal = PoseGoal(x=x, y=y, yaw=yaw, position_tolerance_m=POSITION_TOLERANCE_M,
                        yaw_tolerance_rad=TURN_TOLERANCE_RAD)  # fmt: skip
        self.goal_id = self.port.send_nav_goal(goal)
        self.turn_mark = None

    def _glance(self, pid: str, people: list[MapEntity], may_start: bool) -> bool:
        """While asking: turn the head camera to a body the lidars track near that it does
        not see and the map cannot name (`person_search.glance_at`), and look there
        `GLANCE_LOOK_S`; whether such a turn or look is under way. A turn held still
        `TURN_HELD_S` ends (a person beside the robot). A new one begins only while
        `may_start` (the ask's time is not up: a busy aisle does not keep it for good)."""
        now = self.port.now_ns
        if self.goal_id:
            status = self.port.nav_status(self.goal_id)
            if status is None or status.state in ("idle", "active"):
                return not self._held(pid, "looking at who walks by")
            self.goal_id = ""
            self.glance_until_ns = now + round(GLANCE_LOOK_S * NS_PER_S)
        if now < self.glance_until_ns:
            return True
        xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
        if not may_start or xy is None or yaw is None:
            return False
        target = glance_at(self.port.bodies(), people, xy, yaw, now, self.glanced)
        if target is None:
            return False
        body, aim = target
        self.glanced[body.id] = (body.x, body.y)
        try:
            self._turn_to(xy[0], xy[1], aim)
        except PortError as exc:
            self.ctx.decide(f"look_for_person: navigation did not take the turn to a body "
                            f"({exc})")  # fmt: skip
            return False
        off = math.degrees(math.remainder(aim - yaw, math.tau))
        self.ctx.decide(
            f"look_for_person: somebody the lidars track at ({body.x:.2f}, {body.y:.2f}), "
            f"{math.dist(xy, (body.x, body.y)):.1f} m off and out of the camera's view "
            f"({body.id}): turning {off:+.0f}° to see if it is {pid} ({self.goal_id})"
        )
        return True

    def _held(self, pid: str, then: str = "") -> bool:
        """Whether the turn under way has been held still `TURN_HELD_S` (then it ends:
        cancelled, said; `then`: what the robot does next, else ask from here)."""
        yaw, now = self.port.robot_yaw(), self.port.now_ns
        if yaw is None:
            return False
        mark = self.turn_mark
        if mark is None or abs(math.remainder(yaw - mark[0], math.tau)) >= TURN_PROGRESS_RAD:
            self.turn_mark = (yaw, now)
            return False
        if now - mark[1] < TURN_HELD_S * NS_PER_S:
            return False
        self._cancel(f"the turn held still {TURN_HELD_S:.0f} s")
        then = then or f"asking for {pid} from here"
        self.ctx.decide(f"look_for_person: the turn did not turn in {TURN_HELD_S:.0f} s (the "
                        f"speed rules hold it for a person beside the robot): {then}")  # fmt: skip
        return True

    def _cancel(self, why: str) -> None:
        if self.goal_id:
            self.port.cancel_nav(self.goal_id, why)
            self.goal_id = ""
        self.turns = []

    def _done(self) -> Status:
        self._cancel("the person was seen")
        self.set(UNSEEN, False)
        self.set(LOOK_AT, None)
        return Status.SUCCESS

    def _not_seen(self, pid: str, person: MapEntity | None) -> Status:
        """Not seen: the next of their usual places to look at (`LOOK_AT`,
        `person_search.next_place`), or, none left, where the map last had them."""
        self._done()
        xy = self.port.robot_xy()
        looked = list(self.get(LOOKED) or [])
        if xy is not None and all(math.dist(xy, q) > LOOKED_M for q in looked):
            looked.append(xy)  # a place once, however many rounds waited there
        place = None if person is None else next_place(person.places, looked, xy)
        if place is None:
            self.ctx.decide(f"{pid} not seen: walking to where the map last had them")
        else:
            looked.append(place.xy)
            self.set(LOOK_AT, place)
            ago = (self.port.now_ns - place.last_seen_ns) / 1e9
            self.ctx.decide(
                f"{pid} not seen: looking at a usual place of theirs, "
                f"({place.xy[0]:.2f}, {place.xy[1]:.2f}): seen there {place.sightings} times, "
                f"last {ago:.0f} s ago"
            )
        self.set(LOOKED, looked)
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        self._cancel("look_for_person stopped")


class BackOff(MissionBehaviour):
    def __init__(
        self,
        ctx: Context,
        stage: str,
        name: str = "back_off",
        distance: Callable[[MissionBehaviour], float] | None = None,
    ) -> None:
        super().__init__(name, ctx, stage)
        #: m to back off (None: `back_off_speed` for `back_off_s`).
        self.distance = distance
        self.duration_s = 0.0

    def initialise(self) -> None:
        super().initialise()
        s = self.settings
        want = s.back_off_speed * s.back_off_s if self.distance is None else self.distance(self)
        room = self._room(want)
        self.duration_s = room / s.back_off_speed
        if room < want:
            self.ctx.decide(f"back off {room:.2f} m, not {want:.2f} m: the map has an "
                            "obstacle behind")  # fmt: skip

    def _room(self, want_m: float) -> float:
        """How far back the map lets the footprint go (`room_behind`); none when the map
        or the pose is not at hand (backing up blind is what walked into a wall)."""
        xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
        try:
            grid = self.port.occupancy()
        except Unavailable:
            return 0.0
        if xy is None or yaw is None:
            return 0.0
        cells = np.asarray(as_numpy(grid.cells), np.uint8)
        return room_behind(cells, grid.resolution_m, grid.origin_xy, xy, yaw, want_m)

    def update(self) -> Status:
        if self.elapsed_s() >= self.duration_s:
            self.port.command_velocity(0.0, 0.0, 0.0)
            return Status.SUCCESS
        self.port.command_velocity(-self.settings.back_off_speed, 0.0, 0.0)
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        self.port.command_velocity(0.0, 0.0, 0.0)
