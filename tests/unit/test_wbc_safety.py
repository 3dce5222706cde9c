"""The fallbacks: damping, and the stand hold that takes over from a failed QP."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from common import robot
from services.wbc.model import RobotModel
from services.wbc.safety import StandHold, damp_command, static_feedforward
from services.wbc.values import JAW


def test_damping_commands_no_torque_and_no_stiffness() -> None:
    cmd = damp_command(robot.POSTURES["stand"])
    assert not cmd.tau_ff.any() and not cmd.kp.any() and cmd.kd.min() > 0


def test_the_stand_holds_feedforward_is_static_equilibrium_on_four_feet() -> None:
    m = RobotModel()
    m.update(robot.standing_q(), np.zeros(m.nv))
    tau = static_feedforward(m)
    g = pin.computeGeneralizedGravity(m.model, m.model.createData(), m.q)
    # some foot forces f carry the base and make the joints' torques exactly tau
    f = np.linalg.lstsq(m.Jc[:, :6].T, g[:6], rcond=None)[0]
    np.testing.assert_allclose(m.Jc[:, :6].T @ f, g[:6], atol=1e-6)
    np.testing.assert_allclose(tau, g[6:] - m.Jc[:, 6:].T @ f, atol=1e-9)
    assert np.all(f[2::3] > 0), "every foot pushes on the ground"
    assert np.all(np.abs(tau) <= robot.TORQUE_LIMITS)


def test_the_stand_hold_holds_where_it_engaged_and_keeps_squeezing_a_held_object() -> None:
    m = RobotModel()
    q = robot.standing_q("ready")
    m.update(q, np.zeros(m.nv))
    hold = StandHold()
    hold.engage(m)
    cmd = hold.command(gripper_effort=4.0, gripper_angle=0.0)
    np.testing.assert_allclose(cmd.q_des[:JAW], q[7:-1])
    assert cmd.tau_ff[JAW] == 4.0 and cmd.kp[JAW] == 0.0 and not cmd.qp_ok
    assert hold.command(None, -0.5).q_des[JAW] == -0.5
