"""Small SE(3)/SO(3) helpers that pinocchio does not give in the form dume needs.

Conventions: rotation matrices act on column vectors (`p_a = R_ab @ p_b`), homogeneous
transforms are 4x4 `T_a_b` (frame b expressed in frame a), quaternions in messages are
`xyzw` (pinocchio, rerun, ROS, scipy) and MuJoCo's are `wxyz`; only the two `quat_*_to_*`
shuffles convert between them (at the sim boundary). Angles are in radians. Roll, pitch
and yaw are the fixed-axis x-y-z angles: `R = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)`.
Quaternion and Euler conversions go through `scipy.spatial.transform.Rotation`, imported
on first use (importing `scipy.spatial` takes about 0.2 s).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from common.messages.world import SupportSurface

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def quat_wxyz_to_xyzw(q: npt.ArrayLike) -> FloatArray:
    """MuJoCo quaternion (w, x, y, z) → message/pinocchio quaternion (x, y, z, w)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def quat_xyzw_to_wxyz(q: npt.ArrayLike) -> FloatArray:
    """Message/pinocchio quaternion (x, y, z, w) → MuJoCo quaternion (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def quat_xyzw_to_matrix(q: npt.ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) of a quaternion (x, y, z, w), normalised first; (N, 4) → (N, 3, 3)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_quat(np.asarray(q, dtype=float)).as_matrix())


def matrix_to_quat_xyzw(R: npt.ArrayLike) -> FloatArray:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (3, 3); (N, 3, 3) → (N, 4)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat(canonical=True))


def yaw_of_quat_xyzw(q: npt.ArrayLike) -> float:
    """Heading (rad, `yaw_of`) of the frame a quaternion (x, y, z, w) rotates to, e.g. the
    base's yaw in the world from `Odom.base_orientation_xyzw`."""
    return yaw_of(quat_xyzw_to_matrix(q))


def rpy_of_quat_xyzw(q: npt.ArrayLike) -> FloatArray:
    """(roll, pitch, yaw) in rad of a quaternion (x, y, z, w): R = Rz(yaw) Ry(pitch) Rx(roll),
    pitch in [-pi/2, pi/2]. (N, 4) → (N, 3)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_quat(np.asarray(q, dtype=float)).as_euler("xyz"))


def rot_x(angle: float) -> FloatArray:
    """Rotation by `angle` (rad) about x."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> FloatArray:
    """Rotation by `angle` (rad) about y (positive pitches +x towards -z)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> FloatArray:
    """Rotation by `angle` (rad) about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def make_T(R: npt.ArrayLike | None = None, p: npt.ArrayLike | None = None) -> FloatArray:
    """4x4 homogeneous transform from a rotation matrix and a translation (default identity)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def T_of_pose(position: npt.ArrayLike, quat_xyzw: npt.ArrayLike) -> FloatArray:
    """4×4 of a position and an orientation (x, y, z, w), e.g. an `Odom`'s base."""
    return make_T(quat_xyzw_to_matrix(quat_xyzw), position)


def inv_T(T: npt.ArrayLike) -> FloatArray:
    """Inverse of a 4x4 rigid transform."""
    T = np.asarray(T, dtype=float)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def transform_points(T: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """Points (N, 3) (or one (3,)) in frame b → (N, 3) in frame a, with the 4x4 `T_a_b`."""
    T = np.asarray(T, dtype=float)
    p = np.atleast_2d(np.asarray(points, dtype=float))
    return np.asarray(p @ T[:3, :3].T + T[:3, 3])


def yaw_of(R: npt.ArrayLike) -> float:
    """Heading (rad) of a frame's x axis projected on the world xy plane."""
    R = np.asarray(R, dtype=float)
    return float(np.arctan2(R[1, 0], R[0, 0]))


def yaw_only(T: npt.ArrayLike) -> FloatArray:
    """`base_yaw` from `base`: same origin, the yaw of T, z up (drops roll and pitch)."""
    T = np.asarray(T, dtype=float)
    return make_T(rot_z(yaw_of(T[:3, :3])), T[:3, 3])


def wrap_angle(angle: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return float((angle + np.pi) % (2.0 * np.pi) - np.pi)


def on_surface(
    p: Sequence[float] | npt.NDArray[np.float64], s: SupportSurface, margin_m: float = 0.0
) -> bool:
    """Whether the floor point p (x, y) lies on surface s's rectangle grown by `margin_m`."""
    c, si = np.cos(s.yaw), np.sin(s.yaw)
    dx, dy = float(p[0]) - s.centre_xy[0], float(p[1]) - s.centre_xy[1]
    u, v = c * dx + si * dy, -si * dx + c * dy
    return bool(abs(u) <= s.half_extents[0] + margin_m and abs(v) <= s.half_extents[1] + margin_m)
