"""The whole-body controller's plain values: state in, references, command out, gains.

They mirror the bus messages field by field (`common.messages.sim.RobotState`,
`JointCommand`), so the service maps them one to one; joints are in
`common.robot.JOINT_NAMES` order. The index constants map joint names to positions in
those vectors and in pinocchio's q and v.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common import robot
from common.geometry import FloatArray

#: Joint indices into the 19-vectors (`JOINT_NAMES` order): the jaw, the six arm joints.
JAW = robot.JOINT_NAMES.index(robot.GRIPPER_JOINT)
ARM = slice(
    robot.JOINT_NAMES.index(robot.ARM_JOINTS[0]), robot.JOINT_NAMES.index(robot.ARM_JOINTS[-1]) + 1
)
#: pinocchio's q (26,) and v (25,) start with the free-flyer base (position and quaternion
#: xyzw: 7; linear and angular velocity: 6); the joints follow in `JOINT_NAMES` order.
Q_BASE, V_BASE = 7, 6
#: The arm joints in pinocchio's q and v, and the jaw's velocity in its v.
Q_ARM = slice(Q_BASE + ARM.start, Q_BASE + ARM.stop)
V_ARM = slice(V_BASE + ARM.start, V_BASE + ARM.stop)
V_JAW = V_BASE + JAW


@dataclass
class WbcState:
    """The robot's state, as `RobotState` carries it (joints in `JOINT_NAMES` order)."""

    q: FloatArray  # (19,) rad
    v: FloatArray  # (19,) rad/s
    base_position_in_world: FloatArray  # (3,) m
    base_orientation_xyzw: FloatArray  # (4,)
    base_linear_velocity_in_world: FloatArray  # (3,) m/s
    base_angular_velocity_in_base: FloatArray  # (3,) rad/s


@dataclass
class WbcReferences:
    """What the controller is asked to do this tick.

    cmd_vel: (vx, vy, ωz) in `base_yaw`, m/s and rad/s; zero stands. base_height: m.
    T_world_tcp: (4, 4) target of `gripper_tcp` in world, or None to hold `arm_posture`;
    tcp_twist, tcp_acceleration: (6,) [linear, angular] in world, its feed-forward.
    arm_posture: (6,) arm joint targets, rad. gripper_angle: jaw target, rad, used unless
    gripper_effort (N·m, closing) is set.
    """

    cmd_vel: FloatArray = field(default_factory=lambda: np.zeros(3))
    base_height: float = robot.STAND_BASE_HEIGHT_M
    T_world_tcp: FloatArray | None = None
    tcp_twist: FloatArray | None = None
    tcp_acceleration: FloatArray | None = None
    arm_posture: FloatArray = field(default_factory=lambda: robot.POSTURES["stand"][ARM].copy())
    gripper_angle: float = robot.GRIPPER_CLOSED
    gripper_effort: float | None = None


@dataclass
class WbcCommand:
    """Per joint (19,): τ = τ_ff + kp (q_des − q) + kd (v_des − v), as `JointCommand`."""

    tau_ff: FloatArray
    q_des: FloatArray
    v_des: FloatArray
    kp: FloatArray
    kd: FloatArray
    qp_ok: bool
    qp_status: str
    stance: FloatArray  # (4,) 1 for a stance foot


@dataclass(frozen=True)
class WbcGains:
    """Task gains (kp 1/s², kd 1/s), weights, and the joint PD around the QP's targets."""

    com_kp: float = 100.0
    com_kd: float = 20.0
    com_w: float = 50.0
    base_kp: tuple[float, float, float, float, float, float] = (0, 0, 200, 300, 300, 200)
    base_kd: tuple[float, float, float, float, float, float] = (0, 0, 30, 35, 35, 30)
    base_w: tuple[float, float, float, float, float, float] = (0, 0, 50, 50, 50, 20)
    swing_kp: float = 900.0
    swing_kd: float = 60.0
    swing_w: float = 50.0
    tcp_kp: float = 200.0
    tcp_kd: float = 30.0
    tcp_w: float = 20.0
    tcp_ki: float = 400.0  # 1/s³: integral action on the TCP position (unmodelled payload)
    tcp_integral_max: float = 0.02  # m s per axis: ki × this bounds the integral's 8 m/s²
    posture_kp: float = 100.0
    posture_kd: float = 20.0
    posture_w_legs: float = 0.05
    posture_w_arm: float = 2.0
    posture_w_arm_reaching: float = 0.02  # only breaks ties while the TCP task is on
    joint_kp: float = 10.0
    joint_kd: float = 1.0
    jaw_kp: float = 20.0
    jaw_kd: float = 0.5
    tracking_slack_m: float = 0.1  # the walking CoM reference never leads by more
    stop_decel_mps2: float = 1.0  # a stop keeps the lead within the CoM's stopping distance
    friction_v: float = 0.05  # rad/s: the dry-friction feed-forward's smoothing
