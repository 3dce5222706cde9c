"""What the controller commands when the QP is not in charge: damping, and the stand hold.

- `damp_command`: no torque, joint damping only (mode `damp`, or a state with NaN in it):
  the robot sinks slowly, as a real quadruped's damping mode.
- `StandHold`: the fallback after a failed QP. The joints hold where they were when it
  engaged with stiff PD gains and the static feed-forward of that configuration (gravity
  minus the least-norm vertical foot forces that carry the base), so a QP that cannot be
  solved never drops the robot; the node reports it and leaves the hold after enough
  good solves in a row.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from common import robot
from common.geometry import FloatArray
from services.wbc.model import RobotModel
from services.wbc.values import JAW, WbcCommand

N = len(robot.JOINT_NAMES)


def _per_joint(leg: float, arm: float, jaw: float) -> FloatArray:
    return np.array([leg] * 12 + [arm] * 6 + [jaw])


HOLD_KP = _per_joint(300.0, 50.0, 5.0)  # N m/rad
HOLD_KD = _per_joint(10.0, 2.0, 0.2)  # N m s/rad
DAMP_KD = _per_joint(8.0, 2.0, 0.2)


def damp_command(q: FloatArray) -> WbcCommand:
    """Zero torque, damping towards zero velocity (q_des is ignored with kp = 0)."""
    z = np.zeros(N)
    q_des = np.array(q, dtype=float)
    return WbcCommand(z, q_des, z.copy(), z.copy(), DAMP_KD.copy(), True, "damp", np.ones(4))


def static_feedforward(m: RobotModel) -> FloatArray:
    """Joint torques (19,) that hold the model's configuration still on four feet."""
    data = m.model.createData()
    g = pin.computeGeneralizedGravity(m.model, data, m.q)
    forces = np.linalg.lstsq(m.Jc[:, :6].T, g[:6], rcond=None)[0]
    return np.asarray(g[6:] - m.Jc[:, 6:].T @ forces, dtype=float)


class StandHold:
    """PD about the joints at `engage` time, with their static feed-forward."""

    def __init__(self) -> None:
        self.q_des: FloatArray = robot.POSTURES["stand"].copy()
        self.tau_ff: FloatArray = np.zeros(N)

    def engage(self, m: RobotModel) -> None:
        """Hold the model's current joints (call after the model was updated)."""
        self.q_des = np.array(m.q[7:], dtype=float)
        self.tau_ff = static_feedforward(m)

    def command(self, gripper_effort: float | None, gripper_angle: float) -> WbcCommand:
        tau, q_des, kp, kd = self.tau_ff.copy(), self.q_des.copy(), HOLD_KP.copy(), HOLD_KD.copy()
        if gripper_effort is not None:  # keep squeezing what is held
            tau[JAW], kp[JAW] = gripper_effort, 0.0
        else:
            tau[JAW], q_des[JAW] = 0.0, gripper_angle
        return WbcCommand(tau, q_des, np.zeros(N), kp, kd, False, "stand hold", np.ones(4))
