"""Small SE(3)/SO(3) helpers that pinocchio does not give in the form dume needs.

Conventions: rotation matrices act on column vectors (`p_a = R_ab @ p_b`), homogeneous
transforms are 4x4 `T_a_b` (frame b expressed in frame a), quaternions in messages are
`xyzw` (pinocchio, rerun, ROS) and MuJoCo's are `wxyz`; only these two helpers convert.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def quat_wxyz_to_xyzw(q: npt.ArrayLike) -> FloatArray:
    """MuJoCo quaternion (w, x, y, z) → message/pinocchio quaternion (x, y, z, w)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def quat_xyzw_to_wxyz(q: npt.ArrayLike) -> FloatArray:
    """Message/pinocchio quaternion (x, y, z, w) → MuJoCo quaternion (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def quat_xyzw_to_matrix(q: npt.ArrayLike) -> FloatArray:
    """Rotation matrix of a unit quaternion (x, y, z, w); the quaternion is normalised."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat_xyzw(R: npt.ArrayLike) -> FloatArray:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    t = np.trace(R)
    if t > 0.0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4, (R[1, 0] - R[0, 1]) / s]
    out = np.array(q)
    out /= np.linalg.norm(out)
    return -out if out[3] < 0.0 else out


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


def inv_T(T: npt.ArrayLike) -> FloatArray:
    """Inverse of a 4x4 rigid transform."""
    T = np.asarray(T, dtype=float)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


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
