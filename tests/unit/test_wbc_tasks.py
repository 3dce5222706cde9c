"""Every WBC task's Jacobian and drift agree with finite differences of its own quantity."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from common import robot
from common.geometry import rot_z
from services.wbc.model import RobotModel
from services.wbc.tasks import ComTask, FrameTask, PostureTask, Task

EPS = 1e-6


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def random_state(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = robot.standing_q(x=0.3, y=-0.2, yaw=0.4)
    q[7:] += rng.uniform(-0.4, 0.4, 19)
    q[3:7] = pin.Quaternion(pin.exp3(rng.normal(0.0, 0.2, 3)) @ rot_z(0.4)).coeffs()
    return q, rng.normal(0.0, 1.0, 25)


def quantity(task: Task, m: RobotModel) -> tuple[np.ndarray, np.ndarray | None]:
    """The task's current value: a position vector, and a rotation when it has one."""
    if isinstance(task, FrameTask):
        fs = m.frames[task.frame]
        return fs.p.copy(), fs.R.copy()
    if isinstance(task, ComTask):
        return m.com.copy(), None
    return m.q[7:].copy(), None


def tangent_difference(task: Task, m: RobotModel, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(value(q1) − value(q0)) in the task's tangent space (world-axes rotation vector)."""
    m.update(q0, np.zeros(25))
    p0, R0 = quantity(task, m)
    m.update(q1, np.zeros(25))
    p1, R1 = quantity(task, m)
    if R0 is None or R1 is None:
        return p1 - p0
    return np.concatenate([p1 - p0, pin.log3(R1 @ R0.T)])


TASKS = [
    *(FrameTask(f, 1.0, 1.0, 1.0) for f in (*robot.FOOT_FRAMES, robot.BASE_FRAME, robot.TCP_FRAME)),
    ComTask(1.0, 1.0, 1.0),
    PostureTask(robot.POSTURES["stand"], 1.0, 1.0, 1.0),
]


@pytest.mark.parametrize("task", TASKS, ids=lambda t: getattr(t, "frame", type(t).__name__))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_task_jacobian_matches_finite_differences(model: RobotModel, task: Task, seed: int) -> None:
    q, _ = random_state(seed)
    model.update(q, np.zeros(25))
    J = task.compute_jacobian(model).copy()
    rng = np.random.default_rng(100 + seed)
    for _ in range(3):
        dq = rng.normal(0.0, 1.0, 25)
        fd = tangent_difference(task, model, q, pin.integrate(model.model, q, EPS * dq)) / EPS
        np.testing.assert_allclose(fd, J @ dq, atol=1e-4 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("task", TASKS[:-1], ids=lambda t: getattr(t, "frame", type(t).__name__))
def test_task_drift_is_the_velocitys_rate_at_zero_acceleration(
    model: RobotModel, task: Task
) -> None:
    q, v = random_state(7)
    model.update(q, v)
    drift = task.compute_drift(model).copy()
    vel0 = task.compute_velocity(model).copy()
    model.update(pin.integrate(model.model, q, EPS * v), v)
    vel1 = task.compute_velocity(model).copy()
    np.testing.assert_allclose(
        (vel1 - vel0) / EPS, drift, atol=1e-3 * max(1.0, np.abs(drift).max())
    )


def test_frame_task_error_is_zero_at_its_target_and_points_to_it(model: RobotModel) -> None:
    q, _ = random_state(3)
    model.update(q, np.zeros(25))
    task = FrameTask(robot.TCP_FRAME, 1.0, 1.0, 1.0)
    fs = model.frames[robot.TCP_FRAME]
    task.set_target(fs.p, fs.R)
    np.testing.assert_allclose(task.compute_error(model), 0.0, atol=1e-12)
    # A small step along J⁺ e moves the frame towards a displaced target.
    task.set_target(
        fs.p + np.array([0.01, -0.02, 0.01]), pin.exp3(np.array([0.02, 0.0, -0.03])) @ fs.R
    )
    e0 = task.compute_error(model).copy()
    dq = np.linalg.pinv(task.compute_jacobian(model)) @ e0
    model.update(pin.integrate(model.model, q, dq), np.zeros(25))
    assert np.linalg.norm(task.compute_error(model)) < 0.05 * np.linalg.norm(e0)


def test_model_mass_matrix_is_symmetric(model: RobotModel) -> None:
    q, v = random_state(5)
    model.update(q, v)
    np.testing.assert_allclose(model.M, model.M.T, atol=1e-12)


@pytest.mark.parametrize("frame", [robot.FOOT_FRAMES[0], robot.TCP_FRAME])
def test_frame_task_fast_rows_equal_the_generic_definition(model: RobotModel, frame: str) -> None:
    q, v = random_state(11)
    model.update(q, v)
    task = FrameTask(frame, np.arange(1.0, 7.0), np.arange(2.0, 8.0), 1.0)
    task.set_target(np.array([0.4, 0.1, 0.7]), rot_z(0.3))
    task.v_ref[:] = np.linspace(-1.0, 1.0, 6)
    task.a_ff[:] = np.linspace(2.0, -2.0, 6)
    fast = task.compute_rows(model)
    generic = Task.compute_rows(task, model)
    np.testing.assert_allclose(fast.J, generic.J)
    np.testing.assert_allclose(fast.b, generic.b, atol=1e-12)


def test_model_views_follow_each_update(model: RobotModel) -> None:
    for seed in (12, 13):
        q, v = random_state(seed)
        model.update(q, v)
        data = model.model.createData()
        np.testing.assert_allclose(model.M, pin.crba(model.model, data, q), atol=1e-10)
        np.testing.assert_allclose(model.h, pin.nonLinearEffects(model.model, data, q, v))
        np.testing.assert_allclose(model.com, pin.centerOfMass(model.model, data, q))


def test_com_and_posture_fast_rows_equal_the_generic_definition(model: RobotModel) -> None:
    q, v = random_state(14)
    model.update(q, v)
    rng = np.random.default_rng(14)
    for task in (ComTask(3.0, 4.0, 1.0), PostureTask(robot.POSTURES["ready"], 5.0, 6.0, 1.0)):
        task.v_ref[:] = rng.normal(size=task.dim)
        task.a_ff[:] = rng.normal(size=task.dim)
        fast, generic = task.compute_rows(model), Task.compute_rows(task, model)
        np.testing.assert_allclose(fast.J, generic.J)
        np.testing.assert_allclose(fast.b, generic.b, atol=1e-12)


def test_a_frame_task_gives_only_its_weighted_rows(model: RobotModel) -> None:
    q, v = random_state(15)
    model.update(q, v)
    task = FrameTask(robot.FOOT_FRAMES[1], 2.0, 3.0, 0.0)
    assert not task.active
    task.set_weight(5.0, slice(0, 3))  # a swing foot: position only
    full = Task.compute_rows(task, model)
    rows = task.compute_rows(model)
    assert task.active and rows.J.shape == (3, 25)
    np.testing.assert_allclose(rows.J, full.J[:3])
    np.testing.assert_allclose(rows.b, full.b[:3], atol=1e-12)
    np.testing.assert_allclose(rows.w, 5.0)
