"""The arm goals' intake: refusals by mode, and goals due at their effective tick in order."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from common.bus import RequestError
from common.messages.wbc import ArmGoalRequest, Grasp, Posture, Reach, Release, WbcModeName
from services.wbc.goals import GoalIntake

LOG = logging.getLogger("test_wbc_goals")
MS = 1_000_000


def _intake(mode: WbcModeName) -> GoalIntake:
    return GoalIntake(lambda: mode, LOG)


def test_goals_are_due_at_their_effective_tick_in_the_order_they_came() -> None:
    intake = _intake("manipulate")
    for req in (
        ArmGoalRequest(goal=Posture(name="ready"), effective_ns=30 * MS),
        ArmGoalRequest(goal=Grasp(), effective_ns=10 * MS),
        ArmGoalRequest(goal=Release()),  # at once
        ArmGoalRequest(goal=Posture(name="stow"), effective_ns=10 * MS),
    ):
        assert intake.accept(req).accepted
    assert [p[0] for p in intake.due(0)] == ["arm_3"]
    assert intake.due(9 * MS) == []
    due = intake.due(20 * MS)
    assert [(goal_id, type(goal).__name__) for goal_id, goal, _ in due] == [
        ("arm_2", "Grasp"),
        ("arm_4", "Posture"),
    ]
    assert [p[0] for p in intake.due(30 * MS)] == ["arm_1"] and intake.due(40 * MS) == []


def _reach(H: np.ndarray) -> ArmGoalRequest:
    H16 = tuple(float(x) for x in H.ravel())
    return ArmGoalRequest(goal=Reach(H=H16, frame="world", stamp_ns=0))


@pytest.mark.parametrize(
    ("mode", "req", "code"),
    [
        ("manipulate", None, "malformed"),
        ("damp", ArmGoalRequest(goal=Release()), "unavailable"),
        ("walk", _reach(np.eye(4)), "busy"),
        ("manipulate", _reach(2.0 * np.eye(4)), "invalid"),
    ],
)
def test_refused_goals_are_not_queued(
    mode: WbcModeName, req: ArmGoalRequest | None, code: str
) -> None:
    intake = _intake(mode)
    with pytest.raises(RequestError) as refused:
        intake.accept(req)
    assert refused.value.code == code and intake.due(10**12) == []


def test_the_mode_is_read_as_the_request_comes() -> None:
    mode: list[WbcModeName] = ["damp"]
    intake = GoalIntake(lambda: mode[0], LOG)
    with pytest.raises(RequestError):
        intake.accept(ArmGoalRequest(goal=Release()))
    mode[0] = "stand"
    assert intake.accept(ArmGoalRequest(goal=Release())).goal_id == "arm_1"
