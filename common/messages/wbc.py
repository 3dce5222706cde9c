"""The whole-body controller's inputs (cmd_vel, mode, arm goals) and its status."""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from common.messages.base import Finite, Mat4, Message, NonNegative, StampNs, Vec3

#: A goal's share of the arm's speeds (0, 1]: a client slows the arm near people.
SpeedShare = Annotated[float, msgspec.Meta(gt=0.0, le=1.0)]

WbcModeName = Literal["damp", "stand", "walk", "manipulate"]


class WbcMode(Message, frozen=True):
    """`dume/<r>/wbc/mode`: the mode and which `cmd_vel` source to obey."""

    stamp_ns: StampNs
    mode: WbcModeName
    cmd_vel_source: str = "navigation"


class CmdVel(Message, frozen=True):
    """`dume/<r>/wbc/cmd_vel`: base velocity in `base_yaw`.

    vx, vy: m/s forward and left. wz: rad/s counter-clockwise.
    source: who sends it; the WBC obeys only the source named by the mode.
    mode: a mode change the source asks for at this tick, applied like one on `wbc/mode`
        (at its stamp plus the mode source's latency, obeyed or not). A lockstep source
        sends its mode changes here: one key keeps the order of its mode and its velocity,
        which two keys do not.
    """

    stamp_ns: StampNs
    vx: Finite
    vy: Finite
    wz: Finite
    source: str
    mode: WbcMode | None = None


class Reach(Message, frozen=True, tag="reach"):
    """Move `gripper_tcp` to H (row-major 4×4) in `frame` (base or world) as of `stamp_ns`.

    A base-frame goal is fixed in the world from the base pose at its stamp. `world` is
    the WBC's: the odometry's frame (`odom`); a client planning in the map converts with
    the localization's T_odom_map (`services.mission.robot.BusRobot.send_arm_goal`).
    approach_axis: unit vector in H's frame along which the gripper approaches;
    pregrasp_m: the approach starts this far back along it.
    speed: the share of the arm's speeds it moves at (the mission's, near people).
    jaw: how far an empty jaw opens for it: `open` (`robot.GRIPPER_OPEN`) or `wide`
    (`robot.GRIPPER_WIDE`, for a box taken from above).
    """

    H: Mat4
    frame: Literal["base", "world"]
    stamp_ns: StampNs
    approach_axis: Vec3 = (1.0, 0.0, 0.0)
    pregrasp_m: NonNegative = 0.08
    speed: SpeedShare = 1.0
    jaw: Literal["open", "wide"] = "open"


class Grasp(Message, frozen=True, tag="grasp"):
    """Close the gripper with a torque limit until held or fully closed."""

    max_effort: NonNegative = 10.0


class Release(Message, frozen=True, tag="release"):
    """Open the gripper."""


class Posture(Message, frozen=True, tag="posture"):
    """Go to a named arm posture: stow, ready, look, handover; at `speed`, the share of
    the arm's joint rate (the mission's, near people)."""

    name: Literal["stow", "ready", "look", "handover"]
    speed: SpeedShare = 1.0


ArmGoal = Reach | Grasp | Release | Posture


class ArmGoalRequest(Message, frozen=True):
    """`dume/<r>/wbc/arm_goal` (query).

    effective_ns: the sender's tick plus its lockstep latency: the controller starts the
    goal at its first tick at or after it (in lockstep the sim cannot get there before
    the sender's ack, which follows the reply), so the same run starts it at the same
    tick. None: at the controller's next tick (a person's or a trial's goal).
    """

    goal: ArmGoal
    effective_ns: StampNs | None = None


class ArmGoalReply(Message, frozen=True):
    """Accepted with a goal id, or refused with a reason."""

    accepted: bool
    goal_id: str = ""
    reason: str = ""


GoalState = Literal["active", "succeeded", "failed", "cancelled"]


class GoalStatus(Message, frozen=True):
    """One arm goal: id, kind (reach, grasp, …), state, and the reason when it failed.

    miss_m: a failed reach's distance from its goal when it gave up, m (0 otherwise).
    """

    goal_id: str
    kind: str
    state: GoalState
    reason: str = ""
    miss_m: NonNegative = 0.0


class WbcStatus(Message, frozen=True):
    """`dume/<r>/wbc/status`: what the controller does and how well.

    base_error_m, gripper_error_m, gripper_error_rad: tracking errors now.
    qp_time_us: the last tick's build + solve time, µs (wall clock, for monitoring).
    tick_us: the last tick's whole compute, state in to command out, µs (wall clock; the
    waits for upstream inputs left out).
    contacts: FL, FR, RL, RR in stance. held: the grasp detector says an object is held.
    gripper_wrench: (6,) force N and torque N·m felt at gripper_tcp, in the base frame.
    reason: the last mode change or failure, for a person.
    calibrating: the odometry is learning the IMU's bias at rest; the gait holds still
    until it is done (`wbc.estimator.calibrate_timeout_s` at most).
    """

    stamp_ns: StampNs
    mode: WbcModeName
    cmd_vel_source: str
    goals: list[GoalStatus]
    base_error_m: NonNegative
    gripper_error_m: NonNegative
    gripper_error_rad: NonNegative
    qp_time_us: NonNegative
    qp_failures: int
    contacts: tuple[bool, bool, bool, bool]
    gripper_angle: Finite
    gripper_effort: Finite
    held: bool
    gripper_wrench: tuple[Finite, Finite, Finite, Finite, Finite, Finite]
    reason: str = ""
    tick_us: NonNegative = 0.0
    calibrating: bool = False

    WALL_CLOCK = ("qp_time_us", "tick_us")
