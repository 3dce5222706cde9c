"""The WBC's values on and off the wire: `RobotState` → `WbcState`, `WbcCommand` →
`JointCommand`.

The joint vectors travel as `common.messages.Array` (little-endian float64, shape (19,),
`common.robot.JOINT_NAMES` order). These helpers do what `as_numpy` and `to_wire` do for
exactly that shape, with fewer checks, since they run twice a tick on the critical path.
Pure functions: any thread may call them.
"""

from __future__ import annotations

import numpy as np

from common import robot
from common.geometry import FloatArray
from common.messages import Array, ArrayError
from common.messages.sim import JointCommand, RobotState, StateTruth
from services.wbc.values import WbcCommand, WbcState

#: The service's name: its lockstep participant, and the `source` of its commands.
NAME = "wbc"

_F64 = np.dtype("<f8")
_JOINTS = (len(robot.JOINT_NAMES),)
_UPRIGHT = np.array([0.0, 0.0, 0.0, 1.0])
#: Bytes of one joint vector on the wire: 19 float64.
_JOINT_BYTES = len(robot.JOINT_NAMES) * _F64.itemsize


def _joints_in(array: Array, name: str) -> FloatArray:
    """A joint vector off the wire (a read-only view), checked as `as_numpy` would, fast."""
    if array.dtype != "float64" or tuple(array.shape) != _JOINTS or len(array.data) != _JOINT_BYTES:
        raise ArrayError(f"{name} must be float64 {_JOINTS}, got {array.dtype} {array.shape}")
    return np.frombuffer(array.data, dtype=_F64)


def _joints_out(x: FloatArray) -> Array:
    """A joint vector on the wire (what `to_wire` does for a float64 (19,), without checks)."""
    return Array("float64", _JOINTS, x.astype(_F64, copy=False).tobytes())


def wbc_state(msg: RobotState, base: StateTruth | None = None) -> WbcState:
    """The controller's view of a state; ArrayError when its joint vectors are malformed.

    q (rad) and v (rad/s) are read-only views into the message's bytes. The base's pose
    and twist (world frame, the angular velocity in the base) are the truth ablation's
    `base`, or at rest at the origin for the odometry to fill in (`odometry.predict`).
    """
    q, v = _joints_in(msg.q, "q"), _joints_in(msg.v, "v")
    if base is None:
        return WbcState(q, v, np.zeros(3), _UPRIGHT.copy(), np.zeros(3), np.zeros(3))
    return WbcState(
        q=q,
        v=v,
        base_position_in_world=np.array(base.base_position_in_world),
        base_orientation_xyzw=np.array(base.base_orientation_xyzw),
        base_linear_velocity_in_world=np.array(base.base_linear_velocity_in_world),
        base_angular_velocity_in_base=np.array(base.base_angular_velocity_in_base),
    )


def joint_command(stamp_ns: int, cmd: WbcCommand) -> JointCommand:
    """The command for the state stamped `stamp_ns` (ns of sim time), from `NAME`."""
    return JointCommand(
        stamp_ns=stamp_ns,
        tau_ff=_joints_out(cmd.tau_ff),
        q_des=_joints_out(cmd.q_des),
        v_des=_joints_out(cmd.v_des),
        kp=_joints_out(cmd.kp),
        kd=_joints_out(cmd.kd),
        source=NAME,
    )
