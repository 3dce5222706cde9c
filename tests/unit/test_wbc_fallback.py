"""The QP-failure state machine: one tick's grace, then the stand hold until good solves."""

from __future__ import annotations

import numpy as np

from common import robot
from services.wbc.arm_actions import ArmReferences
from services.wbc.fallback import QpFallback
from services.wbc.model import RobotModel
from services.wbc.values import ARM, JAW, WbcCommand, WbcState

N = len(robot.JOINT_NAMES)


class _Controller:
    """What the fallback uses of `WholeBodyController`: its model, and `reset`."""

    def __init__(self) -> None:
        self.model = RobotModel()
        self.model.update(robot.standing_q(), np.zeros(self.model.nv))
        self.resets: list[WbcState] = []

    def reset(self, state: WbcState) -> None:
        self.resets.append(state)


def _solve(ok: bool) -> WbcCommand:
    z = np.zeros(N)
    return WbcCommand(z, z, z, z, z, ok, "solved" if ok else "primal infeasible", np.ones(4))


def _state() -> WbcState:
    q = robot.POSTURES["stand"].copy()
    zero3 = np.zeros(3)
    return WbcState(q, np.zeros(N), zero3, np.array([0.0, 0.0, 0.0, 1.0]), zero3, zero3)


ARM_REFS = ArmReferences(None, None, None, robot.POSTURES["stand"][ARM], -0.4, None)


def test_two_failed_solves_hand_over_to_the_stand_hold_and_good_solves_give_it_back() -> None:
    ctrl, said = _Controller(), []
    fallback = QpFallback(ctrl, recover_ticks=3, say=said.append)
    state = _state()
    good = _solve(True)
    assert fallback.command(good, state, ARM_REFS) is good
    first = _solve(False)
    assert fallback.command(first, state, ARM_REFS) is first  # the last torques, one tick
    assert not fallback.active and said == [
        "QP failed (primal infeasible): holding the last torques"
    ]
    held = fallback.command(_solve(False), state, ARM_REFS)
    assert fallback.active and held.qp_status == "stand hold" and not held.qp_ok
    np.testing.assert_allclose(held.q_des[:JAW], ctrl.model.q[7:-1])  # where it engaged
    assert held.q_des[JAW] == -0.4  # the jaw keeps its reference
    assert said[-1] == "QP failed 2 ticks: stand hold" and fallback.qp_failures == 2
    assert fallback.command(_solve(False), state, ARM_REFS).qp_status == "stand hold"
    assert len(said) == 2, "a longer failure says nothing more"
    for _ in range(2):  # recover_ticks - 1 good solves: still holding
        assert fallback.command(_solve(True), state, ARM_REFS).qp_status == "stand hold"
    assert fallback.active and not ctrl.resets
    back = _solve(True)
    assert fallback.command(back, state, ARM_REFS) is back
    assert not fallback.active and ctrl.resets == [state]
    assert said[-1] == "QP solves again: whole-body control resumed"
    assert fallback.qp_failures == 3


def test_a_good_solve_between_failures_restarts_the_grace() -> None:
    fallback = QpFallback(_Controller(), recover_ticks=3, say=lambda _reason: None)
    state = _state()
    for _ in range(3):
        fail = _solve(False)
        assert fallback.command(fail, state, ARM_REFS) is fail
        fallback.command(_solve(True), state, ARM_REFS)
    assert not fallback.active and fallback.qp_failures == 3
