"""The wrench felt at `gripper_tcp`, from the arm's joint torques (no force sensor).

The arm's rows of the equations of motion, with an external wrench F (force and torque
at the TCP, world axes) acting on the gripper:

    M_a v̇ + h_a + d ⊙ v_a + f_c tanh(v_a / v_s) = τ_a + J_aᵀ F

where J_a is the TCP's LOCAL_WORLD_ALIGNED Jacobian restricted to the six arm joints, τ_a
the torques the sim applied (`RobotState.tau`), d and f_c the joints' damping and dry
friction. Quasi-statically (M_a v̇ dropped: small when the arm is nearly still, which is
when a person pulls), J_aᵀ F equals the residual r = h_a + d v_a + … − τ_a, and F is its
damped least-squares solution (well defined near singular arm poses), low-pass filtered
and returned in the base frame.
A held 0.5 kg bottle reads as about −5 N along world z.
"""

from __future__ import annotations

import numpy as np

from common.geometry import FloatArray
from services.wbc.values import ARM, V_ARM

#: Rows of v (pinocchio) and columns of the 19-joint vectors for the six arm joints.
ARM_V, ARM_J = V_ARM, ARM


def wrench_from_residual(J_arm: FloatArray, residual: FloatArray, damping: float) -> FloatArray:
    """F (6,) minimising ‖J_armᵀ F − r‖² + damping² ‖F‖² (J_arm: 6×6, world axes)."""
    A = J_arm.T
    return np.asarray(np.linalg.solve(A.T @ A + damping**2 * np.eye(6), A.T @ residual))


class WrenchEstimator:
    """Feed it the model's terms each time; `wrench_in_base` is the filtered estimate."""

    def __init__(
        self,
        joint_damping: FloatArray,
        joint_friction: FloatArray,
        friction_v: float = 0.05,
        damping: float = 0.02,
        alpha: float = 0.3,
    ) -> None:
        self.d = np.asarray(joint_damping, dtype=float)[ARM_J]
        self.fc = np.asarray(joint_friction, dtype=float)[ARM_J]
        self.friction_v = friction_v
        self.damping = damping
        self.alpha = alpha
        self.wrench_in_base: FloatArray = np.zeros(6)
        self._filtered_world: FloatArray | None = None

    def update(
        self,
        h: FloatArray,
        v: FloatArray,
        tau_applied: FloatArray,
        J_tcp: FloatArray,
        R_world_base: FloatArray,
    ) -> FloatArray:
        """h (nv,) and v (nv,) in pinocchio's layout; tau_applied (19,) N·m; J_tcp (6, nv)
        LWA. Returns the filtered wrench [force N, torque N·m] in the base frame."""
        va = v[ARM_V]
        r = h[ARM_V] + self.d * va + self.fc * np.tanh(va / self.friction_v)
        r = r - tau_applied[ARM_J]
        F = wrench_from_residual(J_tcp[:, ARM_V], r, self.damping)
        if self._filtered_world is None:
            self._filtered_world = F
        else:
            self._filtered_world = self._filtered_world + self.alpha * (F - self._filtered_world)
        Rt = R_world_base.T
        w = self._filtered_world
        self.wrench_in_base = np.concatenate([Rt @ w[:3], Rt @ w[3:]])
        return self.wrench_in_base
