"""The leaves that move the arm, only through the whole-body controller's arm goals.

- `ArmAction`: sends one goal (Posture, Reach from the grasp plan, Grasp, Release) on
  start and watches its state on `wbc/status`; a refusal, a failed goal or a goal still
  active after its timeout fails with the action's typed reason. Preempted while its goal
  is active, it asks the port to hold the arm where it is (the controller has no goal
  cancel: leaving `manipulate` freezes the arm's joints). With `must_succeed` False a
  failed goal is said and passed over (SUCCESS, no failure recorded): a best effort;
  with `near_enough_m`, a Reach that gave up within that of its pose is passed over so.
- `GraspReach`: the grasp's Reach; one that gave up farther than `reach_miss_max_m`
  from the grasp pose met something solid or is out of reach: `grasp_pose_failed`, not
  re-picked (hall seed 15: the gripper hit the bench under a tall box 11.7 cm short, and
  the second try tipped the robot over).
- `CheckHeld`: the grasp detector on `wbc/status` says an object is held; where the base
  stands then is kept (`Context.picked_from`: where a put-back walks to), and, by the
  check right after the grasp (not the lift's), where the jaw closed on what
  (`Context.taken`: the map marks the entry there missing; hall seed 0's shift picked
  bottle_1 for a phantom bottle_8 beside it, and the next request walked to bottle_1's
  stale entry and looked at nothing).
- `Seated`: SUCCESS unless a side-grasped cylinder sits more than `seat.SEAT_TOL_M`
  shallower in the jaws than planned, as the jaw's angle says (`seat.seat_x`); then
  FAILURE with the grasp plan re-seated deeper by the difference (`GraspPlan.reseated`,
  at most `RESEAT_MAX_M`), said: the tree opens, moves the jaws deeper and closes again,
  once (`again`: the seat then is read and said, and lifted as it is).
- `StowsHere`: SUCCESS when the arm can fold the held object to `stow` where the base
  stands (`stow_room`); FAILURE with how far the base backs off first (`STOW_BACK`),
  said, when the stowed object would meet the support's edge: the tree then pulls the
  object back, backs the base off and stows.
- `NoCloseIn`: SUCCESS when the grasp plan has no close-in move (a narrow cylinder's
  side grasp), so the tree skips it; FAILURE when it has one (a box, a wide cylinder:
  `GraspPlan.closed_in`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from py_trees.common import Status

from common import robot
from common.messages.arrays import as_numpy
from common.messages.mission import TAKEN_KEPT, MissionReason, Taken
from common.messages.wbc import ArmGoal
from services.mission import seat
from services.mission.behaviours.base import (
    GRASP_PLAN,
    STOW_BACK,
    TARGET,
    Context,
    MissionBehaviour,
    Target,
)
from services.mission.ports import PortError, Refused
from services.mission.stow_room import stow_back_off_m, support_ahead_m

GoalOf = Callable[[MissionBehaviour], ArmGoal]


class ArmAction(MissionBehaviour):
    def __init__(
        self,
        ctx: Context,
        name: str,
        goal: GoalOf,
        reason: MissionReason,
        timeout_s: float,
        stage: str,
        must_succeed: bool = True,
        near_enough_m: float = 0.0,
    ) -> None:
        super().__init__(name, ctx, stage)
        self.goal_of, self.reason, self.timeout_s = goal, reason, timeout_s
        self.must_succeed, self.near_enough_m = must_succeed, near_enough_m
        self.goal_id = ""
        self.active = False
        self.error: str = ""

    def initialise(self) -> None:
        super().initialise()
        self.goal_id, self.active, self.error = "", False, ""
        try:
            goal = self.goal_of(self)
            self.goal_id = self.port.send_arm_goal(goal)
            self.active = True
            self.ctx.decide(f"{self.name}: {type(goal).__name__} sent as {self.goal_id}")
        except Refused as exc:
            self.error = f"the controller refused it: {exc}"
        except PortError as exc:
            self.error = f"no answer from the controller: {exc}"

    def update(self) -> Status:
        if self.error:
            return self.fail(self.reason if "refused" in self.error else "unavailable", self.error)
        goal = self.port.arm_goal(self.goal_id)
        if goal is not None and goal.state == "succeeded":
            self.active = False
            self.feedback_message = f"{self.goal_id} succeeded"
            return Status.SUCCESS
        if goal is not None and goal.state in ("failed", "cancelled"):
            self.active = False
            near = goal.kind == "reach" and goal.state == "failed"
            if not self.must_succeed or (near and goal.miss_m <= self.near_enough_m):
                self.ctx.decide(f"{self.name}: {goal.kind} {goal.state}: {goal.reason}; going on")
                return Status.SUCCESS
            return self.fail(self.reason, f"{goal.kind} {goal.state}: {goal.reason}")
        if self.elapsed_s() > self.timeout_s:
            return self.fail(self.reason, f"still not done after {self.elapsed_s():.1f} s")
        self.feedback_message = f"{self.goal_id} active"
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        if self.active and new_status != Status.SUCCESS:
            self.port.hold_arm(f"{self.name} stopped")
            self.ctx.decide(f"{self.name}: arm held where it is")
        self.active = False


class GraspReach(ArmAction):
    """See the module docstring."""

    def __init__(self, ctx: Context, goal: GoalOf, stage: str) -> None:
        super().__init__(ctx, "reach", goal, "grasp_failed", ctx.settings.reach_timeout_s, stage)

    def update(self) -> Status:
        goal = self.port.arm_goal(self.goal_id) if self.goal_id else None
        limit = self.settings.reach_miss_max_m
        if goal is not None and goal.state == "failed" and goal.miss_m > limit:
            self.active = False
            return self.fail(
                "grasp_pose_failed",
                f"the gripper stopped {goal.miss_m * 100:.1f} cm from the grasp pose (more than "
                f"{limit * 100:.0f} cm): blocked or out of reach, not tried again",
            )
        return super().update()


class CheckHeld(MissionBehaviour):
    def __init__(
        self, ctx: Context, stage: str, name: str = "check_held", take: bool = True
    ) -> None:
        super().__init__(name, ctx, stage)
        #: Whether this check notes the take (the first after the grasp, not the lift's).
        self.take = take

    def update(self) -> Status:
        status = self.port.wbc_status()
        if status is not None and status.held:
            xy, yaw = self.port.robot_xy(), self.port.robot_yaw()
            self.ctx.picked_from = None if xy is None or yaw is None else (*xy, yaw)
            if self.take:
                self._note_taken()
            return Status.SUCCESS
        effort = "no wbc/status" if status is None else f"effort {status.gripper_effort:.2f}"
        return self.fail("grasp_failed", f"the grasp detector does not say held ({effort})")

    def _note_taken(self) -> None:
        """Keep the take (`Context.taken`): where the grasp plan's jaw closed, on what."""
        plan, target = self.get(GRASP_PLAN), self.get(TARGET)
        if plan is None or plan.frame != "world" or not isinstance(target, Target):
            return
        x, y = (float(v) for v in np.asarray(plan.closed_in().H, dtype=float)[:2, 3])
        taken = Taken(stamp_ns=self.port.now_ns, map_id=target.map_id,
                      class_name=target.class_name, xy=(x, y))  # fmt: skip
        self.ctx.taken = [*self.ctx.taken, taken][-TAKEN_KEPT:]


class Seated(MissionBehaviour):
    """See the module docstring."""

    WRITES = (GRASP_PLAN,)

    def __init__(self, ctx: Context, stage: str, again: bool = False) -> None:
        super().__init__("seated_again" if again else "seated", ctx, stage)
        #: After the re-seat: the seat is read and said, never taken again.
        self.again = again

    def update(self) -> Status:
        plan, status = self.get(GRASP_PLAN), self.port.wbc_status()
        if plan is None or plan.radius_m <= 0.0 or status is None or not status.held:
            return Status.SUCCESS
        slope = float(np.asarray(plan.H, dtype=float)[2, 0])  # the approach's, up
        if abs(slope) > math.sin(seat.LEVEL_RAD):
            return Status.SUCCESS  # pitched: the jaws' plane crosses the axis, not read
        x = seat.seat_x(status.gripper_angle, plan.radius_m)
        off = x - plan.seat_x_m
        where = (f"the jaw closed at {status.gripper_angle:.3f} rad on the "
                 f"{plan.radius_m * 200:.1f} cm cylinder: its axis {x * 100:+.1f} cm along "
                 f"the jaws, {off * 100:+.1f} cm from the plan")  # fmt: skip
        if off <= seat.SEAT_TOL_M or self.again:
            then = "held there" if off <= seat.SEAT_TOL_M else "lifted as it is, once taken again"
            self.ctx.decide(f"seat: {where}: {then}")
            return Status.SUCCESS
        deeper = min(off, seat.RESEAT_MAX_M)
        self.set(GRASP_PLAN, plan.reseated(deeper))
        self.ctx.decide(f"seat: {where}: taken again {deeper * 100:.1f} cm deeper")
        return Status.FAILURE


class StowsHere(MissionBehaviour):
    """See the module docstring."""

    WRITES = (STOW_BACK,)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("stows_here", ctx, stage)

    def update(self) -> Status:
        self.set(STOW_BACK, 0.0)
        plan, xy, yaw = self.get(GRASP_PLAN), self.port.robot_xy(), self.port.robot_yaw()
        if plan is None or plan.frame != "world" or xy is None or yaw is None:
            return Status.SUCCESS
        try:
            grid = self.port.occupancy()
        except PortError:
            return Status.SUCCESS  # no map: nothing known ahead, stowed as before
        _, lateral, _ = robot.posture_tcp("stow")
        cells = np.asarray(as_numpy(grid.cells), np.uint8)
        edge = support_ahead_m(cells, grid.resolution_m, grid.origin_xy, xy, yaw, lateral)
        grasp_z = float(np.asarray(plan.H, dtype=float)[2, 3])
        back = stow_back_off_m(grasp_z, edge, plan.beyond_m)
        if back <= 0.0:
            return Status.SUCCESS
        self.set(STOW_BACK, back)
        self.ctx.decide(f"stow: the support's edge {edge:.2f} m ahead, the object held "
                        f"{plan.beyond_m * 100:.0f} cm past the TCP from {grasp_z:.2f} m up "
                        f"would meet it: pulled back and the base backed off {back:.2f} m "
                        "first")  # fmt: skip
        return Status.FAILURE


class NoCloseIn(MissionBehaviour):
    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("no_close_in", ctx, stage)

    def update(self) -> Status:
        plan = self.get(GRASP_PLAN)
        return Status.SUCCESS if plan is None or plan.close_in_m <= 0.0 else Status.FAILURE
