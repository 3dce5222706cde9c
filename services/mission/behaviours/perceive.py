"""The leaves that look: the visual approach and the grasp pose.

- `Approach`: each tick the wrist camera's newest detection of the target (by map id,
  else the one at its mapped place, of its class or, failing that, of any artifact class;
  once it fell from the gripper, the nearest of its class: lying lower than any grasp
  reaches, `grasp_pose.below_reach`, it fails `object_dropped` saying where it lies)
  becomes a `Sighting` (none when older than `sighting_max_age_s`); the
  approach controller (eq. 3, with its own re-acquire: turn, back off) turns it into
  cmd_vel, sent as source `mission` (the tree set the mode before) within navigation's
  people caps (a command held back for a person is said, and is no stall for the
  controller: `ApproachController.hold`). `arrived` → stop,
  SUCCESS; `failed` → stop, `object_not_found` with the controller's reason. It never
  freezes: the controller fails by itself, and `approach_timeout_s` bounds it (the time
  held back for people not counted: `approach_held_max_s` bounds that, then it fails
  `blocked_by_person`, and a request by class tries the next instance). Stopped
  other than by arriving, it hands the base back to navigation (mode walk/navigation).
- `EstimateGrasp`: standing still (`settle_s`), the first wrist detection captured after
  that → `grasp_from_detection` → ᴮH_G composed with the base pose at capture: a
  world-fixed goal (so the Reach stays valid while the arm gets ready, and a box's
  world yaw is usable) → the plan and the detection on the blackboard; no
  detection within `detection_timeout_s` → `object_not_found`; no grasp possible →
  `grasp_pose_failed`. A grasp possible from another stance (a box too tall for a top
  grasp, its long faces off the line of sight: `GraspPoseError.stance_yaw_rad`) puts
  that line's world yaw on the blackboard (`STANCE`) first, once per object: the tree
  walks to a standoff at one of its ends (`NoStance` fails), approaches and tries again.
- `NoStance`: SUCCESS unless a grasp asked for a stance (`STANCE`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from py_trees.common import Status

from services.mission.behaviours.base import (
    DETECTION,
    GRASP_PLAN,
    NS_PER_S,
    STANCE,
    Context,
    MissionBehaviour,
)
from services.mission.grasp_pose import below_reach


class Approach(MissionBehaviour):
    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("approach", ctx, stage)
        self.controller: Any = None
        self.state = ""
        self.held = ""

    def initialise(self) -> None:
        super().initialise()
        self.controller = self.ctx.algorithms.approacher()
        self.controller.reset(self.port.now_ns / NS_PER_S)
        self.state = ""
        self.held = ""  # who the base is held back for (navigation's people caps)

    def update(self) -> Status:
        now_ns = self.port.now_ns
        target = self.target()
        # Where it is is all the approach needs, whatever the network calls it there.
        seen = self.port.wrist_detection(target.map_id, target.class_name, target.look_near, True)
        sighting = None
        max_age_ns = round(self.settings.sighting_max_age_s * NS_PER_S)
        if seen is not None and now_ns - seen.stamp_ns <= max_age_ns:
            det = seen.detection
            if target.dropped and (low := below_reach(det)):
                self.port.command_velocity(0.0, 0.0, 0.0)
                x, y = det.centroid_in_world[:2]
                return self.fail(
                    "object_dropped",
                    f"{target.map_id} fell while carried and lies at ({x:.2f}, {y:.2f}) where "
                    f"the robot cannot pick it up: {low}",
                )
            sighting = self.ctx.algorithms.sighting(
                det.d_obj, det.theta_obj, seen.stamp_ns / NS_PER_S
            )
        cmd = self.controller.step(now_ns / NS_PER_S, sighting)
        if cmd.state != self.state:
            self.ctx.decide(f"approach {target.map_id}: {cmd.state} {cmd.reason}".rstrip())
            self.state = cmd.state
        if cmd.state == "arrived":
            self.port.command_velocity(0.0, 0.0, 0.0)
            self.feedback_message = f"arrived {cmd.reason}".rstrip()
            return Status.SUCCESS
        if cmd.state == "failed":
            self.port.command_velocity(0.0, 0.0, 0.0)
            why = cmd.reason or f"{target.map_id} not acquired"
            if target.dropped:
                return self.fail(
                    "object_dropped",
                    f"{target.map_id} fell {target.where_dropped()} while carried and was "
                    f"not found where it fell: {why}",
                )
            return self.fail("object_not_found", why)
        held_s = self.controller.held_s
        if self.elapsed_s() - held_s > self.settings.approach_timeout_s:
            self.port.command_velocity(0.0, 0.0, 0.0)
            also = f" ({held_s:.0f} s more held back for people)" if held_s >= 1.0 else ""
            return self.fail(
                "object_not_found",
                f"no arrival at {target.map_id} in {self.elapsed_s() - held_s:.0f} s{also}",
            )
        if held_s > self.settings.approach_held_max_s:
            self.port.command_velocity(0.0, 0.0, 0.0)
            return self.fail(
                "blocked_by_person",
                f"{target.map_id} not reached: held back for {self.held or 'people'} "
                f"{held_s:.0f} s in all",
            )
        held = self.port.command_velocity(cmd.vx, cmd.vy, cmd.wz)
        if held:
            self.controller.hold(now_ns / NS_PER_S)
        if held != self.held:
            self.ctx.decide(f"approach {target.map_id}: held back for {held}" if held else
                            f"approach {target.map_id}: no longer held back")  # fmt: skip
            self.held = held
        self.feedback_message = f"{cmd.state} {cmd.reason}".rstrip()
        if held:
            self.feedback_message += f" (held back for {held})"
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        self.port.command_velocity(0.0, 0.0, 0.0)
        if self.controller is not None and new_status != Status.SUCCESS:
            self.port.set_mode("walk", "navigation")  # hand the base back to navigation
        self.controller = None


class EstimateGrasp(MissionBehaviour):
    WRITES = (DETECTION, GRASP_PLAN, STANCE)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("estimate_grasp", ctx, stage)

    def update(self) -> Status:
        s = self.settings
        if self.elapsed_s() < s.settle_s:
            self.feedback_message = "standing still"
            return Status.RUNNING
        target = self.target()
        seen = self.port.wrist_detection(target.map_id, target.class_name, target.look_near)
        settled_ns = self.started_ns + round(s.settle_s * NS_PER_S)
        if seen is None or seen.stamp_ns < settled_ns:
            if self.elapsed_s() > s.settle_s + s.detection_timeout_s:
                return self.fail(
                    "object_not_found",
                    f"the wrist camera has not seen {target.map_id} for "
                    f"{s.detection_timeout_s:.1f} s standing still",
                )
            return Status.RUNNING
        stamp, det = seen.stamp_ns, seen.detection
        T_world_base = np.asarray(seen.T_world_base, dtype=float).reshape(4, 4)
        try:
            plan = self.ctx.algorithms.grasp_from_detection(det, stamp, T_world_base)
        except self.ctx.algorithms.grasp_error as exc:
            if target.dropped:  # on the floor, as a rule: a person picks it up
                return self.fail(
                    "object_dropped",
                    f"{target.map_id} fell {target.where_dropped()} while carried and lies "
                    f"where the robot cannot pick it up: {exc}",
                )
            stance = getattr(exc, "stance_yaw_rad", None)
            if stance is not None and self.get(STANCE) is None:
                self.set(STANCE, float(stance))
                return self.fail(
                    "grasp_pose_failed",
                    f"no grasp of {target.map_id} from here: {exc}; walking to a stance "
                    f"with the line of sight along {math.degrees(stance):.0f}°",
                )
            return self.fail("grasp_pose_failed", f"no grasp of {target.map_id}: {exc}")
        self.set(DETECTION, seen)
        self.set(GRASP_PLAN, plan)
        goal = plan.reach()
        tcp = np.asarray(goal.H, dtype=float).reshape(4, 4)[:3, 3]
        if goal.frame == "base":
            tcp = T_world_base[:3, :3] @ tcp + T_world_base[:3, 3]
        seen_at = det.centroid_in_world
        self.ctx.decide(
            f"grasp of {target.map_id}: {plan.kind} from the frame at {stamp / NS_PER_S:.2f} s, "
            f"the TCP to ({tcp[0]:.3f}, {tcp[1]:.3f}, {tcp[2]:.3f}), the object seen at "
            f"({seen_at[0]:.3f}, {seen_at[1]:.3f}, {seen_at[2]:.3f}) (world)"
        )
        return Status.SUCCESS


class NoStance(MissionBehaviour):
    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("no_stance_asked", ctx, stage)

    def update(self) -> Status:
        return Status.SUCCESS if self.get(STANCE) is None else Status.FAILURE
