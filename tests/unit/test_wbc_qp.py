"""The whole-body QP's answer obeys the dynamics, friction cones, force bounds and torque limits."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from common import robot
from services.wbc import constraints as cons
from services.wbc.controller import WholeBodyController
from services.wbc.qp import build_qp

# OSQP stops at eps 1e-3 absolute + 1e-3 relative to rows of ~600 N: < 1 N or N m of slack.
TOL = 1.0


@pytest.fixture(scope="module")
def controller() -> WholeBodyController:
    return WholeBodyController()


def standing_state(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = robot.standing_q()
    q[7:19] += rng.uniform(-0.05, 0.05, 12)  # legs near the stand, arm anywhere reasonable
    q[19:25] += rng.uniform(-0.3, 0.3, 6)
    q[3:7] = pin.Quaternion(pin.exp3(rng.normal(0.0, 0.03, 3))).coeffs()
    v = rng.normal(0.0, 0.1, 25)
    return q, v


@pytest.mark.parametrize(
    "stance", [(1, 1, 1, 1), (1, 0, 0, 1), (0, 1, 1, 0)], ids=["stand", "FL+RR", "FR+RL"]
)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_qp_solution_satisfies_dynamics_cones_and_limits(
    controller: WholeBodyController, stance: tuple[int, ...], seed: int
) -> None:
    c = controller
    m = c.model
    q, v = standing_state(seed)
    m.update(q, v)
    c.base_task.set_target(np.array([0.0, 0.0, robot.STAND_BASE_HEIGHT_M]), np.eye(3))
    c.com_task.p_ref[:2] = m.com[:2]
    s = np.array(stance, dtype=float)
    f_ref = np.zeros(12)
    f_ref[2::3] = s * m.mass * 9.81 / s.sum()
    problem = build_qp(m, c.tasks, s, f_ref, c.qp_params)
    assert c.solver.outside_pattern(problem) == 0.0
    sol = c.solver.solve(problem)
    assert sol.ok, sol.status
    tau = cons.joint_torques(m, sol.vdot, sol.f)
    # Full dynamics: M v̇ + h = Sᵀτ + J_cᵀ f, the base rows unactuated.
    residual = m.M @ sol.vdot + m.h - m.Jc.T @ sol.f
    residual[6:] -= tau
    assert np.abs(residual).max() < TOL
    f = sol.f.reshape(4, 3)
    mu, f_min = c.qp_params.mu, c.qp_params.f_min
    for k in range(4):
        if s[k]:
            assert f[k, 2] >= f_min - TOL
            assert abs(f[k, 0]) <= mu * f[k, 2] + TOL and abs(f[k, 1]) <= mu * f[k, 2] + TOL
            # No slip: the stance foot's acceleration is the slip damping's.
            acc = m.Jc[3 * k : 3 * k + 3] @ sol.vdot + m.dJc_v[3 * k : 3 * k + 3]
            expected = -c.qp_params.k_slip * m.v_feet[3 * k : 3 * k + 3]
            np.testing.assert_allclose(acc, expected, atol=0.1)
        else:
            np.testing.assert_allclose(f[k], 0.0, atol=TOL)
    assert np.all(np.abs(tau) <= robot.TORQUE_LIMITS + TOL)
    # Newton on the whole robot: the feet's forces are its weight plus m times the CoM's
    # acceleration that v̇ gives.
    a_com = m.Jcom @ sol.vdot + m.dJcom_v
    np.testing.assert_allclose(
        f.sum(axis=0), m.mass * (a_com + np.array([0.0, 0.0, 9.81])), atol=1.0
    )


def test_constraint_blocks_have_the_declared_rows(controller: WholeBodyController) -> None:
    m = controller.model
    m.update(*standing_state(4))
    blocks = [
        cons.dynamics(m),
        cons.torque_limits(m, robot.TORQUE_LIMITS),
        cons.contact(m, np.ones(4), 10.0),
        cons.friction(0.6, m.nv),
        cons.force_bounds(np.ones(4), 5.0, 700.0, m.nv),
        cons.joint_limits(m, robot.POSITION_LOWER[:18], robot.POSITION_UPPER[:18], 0.05, 300.0),
    ]
    for name, block in zip(cons.ROWS, blocks, strict=True):
        assert block.A.shape == (cons.ROWS[name], m.nv + cons.NF)
        assert np.all(block.lo <= block.hi)


def test_a_joint_running_into_its_limit_is_braked_by_the_qp(
    controller: WholeBodyController,
) -> None:
    c = controller
    m = c.model
    q, v = standing_state(5)
    arm = 12 + 3  # joint4
    q[7 + arm] = robot.POSITION_UPPER[arm] - 0.01
    v[6 + arm] = 2.0  # 0.01 rad from the limit at 2 rad/s: it must decelerate hard
    m.update(q, v)
    c.base_task.set_target(np.array([0.0, 0.0, robot.STAND_BASE_HEIGHT_M]), np.eye(3))
    c.com_task.p_ref[:2] = m.com[:2]
    c.posture_task.q_ref[arm] = robot.POSITION_UPPER[arm] + 0.5  # and the posture pulls on
    f_ref = np.zeros(12)
    f_ref[2::3] = m.mass * 9.81 / 4
    try:
        sol = c.solver.solve(build_qp(m, c.tasks, np.ones(4), f_ref, c.qp_params))
    finally:
        c.posture_task.q_ref[:] = robot.POSTURES["stand"]
    assert sol.ok, sol.status
    h = c.qp_params.limit_horizon_s
    bound = 2.0 * (robot.POSITION_UPPER[arm] - q[7 + arm] - v[6 + arm] * h) / h**2
    assert sol.vdot[6 + arm] <= max(bound, -c.qp_params.limit_acc_max) + 1.0
    assert sol.vdot[6 + arm] < -50.0  # braking, though the posture task pulls the other way
