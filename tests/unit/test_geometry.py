"""`common.geometry`: the quaternion, yaw and roll/pitch/yaw conversions every service uses.

Quaternions are x y z w (messages, pinocchio, scipy); the checks pin that convention and
compare the scipy-backed conversions with the hand-written ones they replaced (as of
commit dce4c37: `common.geometry`'s matrix formula and Shepperd's method, the benches'
roll/pitch/yaw).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.geometry import (
    FloatArray,
    make_T,
    matrix_to_quat_xyzw,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_matrix,
    rot_x,
    rot_y,
    rot_z,
    rpy_of_quat_xyzw,
    transform_points,
    yaw_of,
    yaw_of_quat_xyzw,
)


def _old_quat_xyzw_to_matrix(q: FloatArray) -> FloatArray:
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _old_rpy(q: FloatArray) -> FloatArray:
    R = _old_quat_xyzw_to_matrix(q)
    roll = math.atan2(R[2, 1], R[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    return np.array([roll, pitch, math.atan2(R[1, 0], R[0, 0])])


def _quats(n: int, seed: int = 0) -> FloatArray:
    """Random quaternions, not normalised (the conversions normalise)."""
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 4)) * rng.uniform(0.5, 2.0, (n, 1))


def test_quaternions_are_xyzw() -> None:
    q = matrix_to_quat_xyzw(rot_z(math.pi / 2))
    np.testing.assert_allclose(q, [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(quat_wxyz_to_xyzw([1.0, 0.0, 0.0, 0.0]), [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(quat_xyzw_to_matrix([0.0, 0.0, 0.0, 1.0]), np.eye(3))


def test_matrix_and_quaternion_conversions_are_the_old_ones() -> None:
    for q in _quats(500):
        R = quat_xyzw_to_matrix(q)
        np.testing.assert_allclose(R, _old_quat_xyzw_to_matrix(q), atol=1e-14)
        back = matrix_to_quat_xyzw(R)
        assert back[3] >= 0.0 and np.linalg.norm(back) == pytest.approx(1.0)
        np.testing.assert_allclose(back, np.sign(q[3]) * q / np.linalg.norm(q), atol=1e-14)


def test_yaw_of_a_quaternion_is_the_heading_of_its_x_axis() -> None:
    for q in _quats(500, seed=1):
        assert yaw_of_quat_xyzw(q) == pytest.approx(yaw_of(_old_quat_xyzw_to_matrix(q)), abs=1e-14)
    tilted = rot_z(2.5) @ rot_y(0.2) @ rot_x(-0.1)
    assert yaw_of_quat_xyzw(matrix_to_quat_xyzw(tilted)) == pytest.approx(2.5, abs=1e-3)
    assert yaw_of_quat_xyzw(3.0 * matrix_to_quat_xyzw(rot_z(-1.0))) == pytest.approx(-1.0)


def test_roll_pitch_yaw_are_fixed_axis_x_y_z() -> None:
    roll, pitch, yaw = 0.3, -0.4, 2.9
    q = matrix_to_quat_xyzw(rot_z(yaw) @ rot_y(pitch) @ rot_x(roll))
    np.testing.assert_allclose(rpy_of_quat_xyzw(q), [roll, pitch, yaw], atol=1e-12)
    for q in _quats(500, seed=2):
        got, old = rpy_of_quat_xyzw(q), _old_rpy(q)
        # equal up to rounding, and where yaw or roll is at ±π, up to the 2π turn
        np.testing.assert_allclose(np.remainder(got - old + math.pi, math.tau) - math.pi, 0.0,
                                   atol=1e-12)  # fmt: skip


def test_transform_points_takes_one_point_or_many() -> None:
    T = make_T(rot_z(math.pi / 2), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(transform_points(T, [1.0, 0.0, 0.0]), [[1.0, 3.0, 3.0]])
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(transform_points(T, pts), [[1.0, 2.0, 3.0], [0.0, 2.0, 3.0]])
