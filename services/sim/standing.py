"""Standing: the PD gains that keep the robot up, and the static feed-forward.

A PD hold alone sags: at kp 300 N m/rad the legs give 4-5 cm under the robot's 61 kg. The
feed-forward `standing_feedforward(q)` removes that error: the joint torques of static
equilibrium, g_j(q) - J_j^T f, with g pinocchio's generalized gravity and f the foot
forces that carry the base (J_b^T f = g_b) at the least norm, i.e. vertical forces under
the feet. With it, `STAND_KP`/`STAND_KD` hold the base within 4 mm of its standing
height (`tests/unit/test_sim_core.py`). The sim's watchdog holds latched positions with
`WATCHDOG_KP`/`WATCHDOG_KD` and no model: it sags but stays up, as a robot's damping mode.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from common import robot
from common.geometry import FloatArray


def _per_joint(leg: float, arm: float, jaw: float) -> FloatArray:
    out = np.array([leg] * len(robot.LEG_JOINTS) + [arm] * len(robot.ARM_JOINTS) + [jaw])
    out.setflags(write=False)
    return out


#: PD gains (N m/rad, N m s/rad) for holding a posture with `standing_feedforward`.
STAND_KP = _per_joint(300.0, 50.0, 5.0)
STAND_KD = _per_joint(10.0, 2.0, 0.2)
#: The watchdog's hold of latched positions (no feed-forward but the jaw's last torque).
WATCHDOG_KP = _per_joint(300.0, 80.0, 5.0)
WATCHDOG_KD = _per_joint(10.0, 3.0, 0.2)


def standing_feedforward(q: FloatArray) -> FloatArray:
    """Joint torques (19,) N m that hold pinocchio configuration q (26,) still on four feet.

    Static equilibrium with the least-norm foot forces; the arm and jaw get their gravity
    torques. q's joints, not the targets, set the torques: pass the posture to hold.
    """
    model, _ = robot.load_pinocchio()
    data = model.createData()
    g = pin.computeGeneralizedGravity(model, data, q)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = np.vstack(
        [
            pin.getFrameJacobian(
                model, data, model.getFrameId(foot), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )[:3]
            for foot in robot.FOOT_FRAMES
        ]
    )
    forces = np.linalg.lstsq(J[:, :6].T, g[:6], rcond=None)[0]
    return np.asarray(g[6:] - J[:, 6:].T @ forces, dtype=float)
