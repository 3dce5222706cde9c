"""Smooth `gripper_tcp` motions in the world: minimum-jerk pose segments and grasp geometry.

A `PoseSegment` goes from one pose to another in `duration` seconds along the quintic
s(τ) (zero velocity and acceleration at both ends): the position on the straight line,
the orientation about the fixed axis of R₀ᵀR₁, so its world angular velocity is
R₀ log3(R₀ᵀR₁) ṡ. `sample(t)` gives the pose and the world twist and acceleration the
frame task feeds forward. `pregrasp` backs a grasp pose off along its approach axis, and
`side_grasp` is the TCP pose that holds an upright cylinder from the side (the jaw pivot
along the cylinder, the approach horizontal), as `common.robot.T_STATOR_TCP` defines it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from common.geometry import FloatArray, make_T
from services.wbc.gait import quintic


class PoseSample(NamedTuple):
    """A 4×4 pose, and the twist (6,) and acceleration (6,) [linear, angular] in world."""

    T: FloatArray
    twist: FloatArray
    acceleration: FloatArray


class PoseSegment:
    """From `T_start` to `T_goal` in `duration` s with a minimum-jerk profile."""

    def __init__(self, T_start: FloatArray, T_goal: FloatArray, duration: float) -> None:
        if duration <= 0.0:
            raise ValueError(f"a pose segment needs a positive duration, got {duration}")
        self.T_start, self.T_goal = np.array(T_start, float), np.array(T_goal, float)
        self.duration = duration
        self._dp = self.T_goal[:3, 3] - self.T_start[:3, 3]
        self._w = pin.log3(self.T_start[:3, :3].T @ self.T_goal[:3, :3])  # in the start frame
        self._w_world = self.T_start[:3, :3] @ self._w

    def sample(self, t: float) -> PoseSample:
        """The pose at t seconds after the start (held at the ends)."""
        T = self.duration
        s, ds, dds = quintic(t / T)
        pose = np.eye(4)
        pose[:3, 3] = self.T_start[:3, 3] + s * self._dp
        pose[:3, :3] = self.T_start[:3, :3] @ pin.exp3(s * self._w)
        twist = np.concatenate([self._dp, self._w_world]) * (ds / T)
        acc = np.concatenate([self._dp, self._w_world]) * (dds / T**2)
        return PoseSample(pose, twist, acc)


def pregrasp(T_grasp: FloatArray, distance: float, approach_axis: FloatArray) -> FloatArray:
    """The pose `distance` m back from `T_grasp` along its approach axis (in its own frame)."""
    out = np.array(T_grasp, float)
    axis = np.asarray(approach_axis, float)
    out[:3, 3] -= distance * (out[:3, :3] @ (axis / np.linalg.norm(axis)))
    return out


def side_grasp(centre: FloatArray, approach_xy: FloatArray) -> FloatArray:
    """TCP pose grasping an upright cylinder at `centre` (3,), approached along `approach_xy`.

    x (approach) horizontal along `approach_xy`, y (jaw pivot) up along the cylinder, z
    = x × y horizontal: the jaws close across the cylinder.
    """
    a = np.array([approach_xy[0], approach_xy[1], 0.0], float)
    x = a / np.linalg.norm(a)
    y = np.array([0.0, 0.0, 1.0])
    return make_T(np.column_stack([x, y, np.cross(x, y)]), centre)
