"""The WBC's per-tick work without the bus: mode changes and arm goals on sim time."""

from __future__ import annotations

import logging

from common import robot
from common.config import WbcSettings
from common.messages import to_wire
from common.messages.sim import RobotState
from common.messages.wbc import ArmGoalRequest, Posture, WbcMode, WbcModeName
from services.wbc.commander import WbcCommander
from services.wbc.wire import wbc_state
from tests.unit.test_wbc_node_wire import state as robot_state

MS = 1_000_000


def _commander(mode: WbcModeName) -> tuple[WbcCommander, RobotState]:
    core = WbcCommander(WbcSettings(initial_mode=mode), {}, 2 * MS, logging.getLogger("test"))
    msg = robot_state(to_wire(robot.POSTURES["stand"]))  # at 2 ms
    assert core.begin(msg.stamp_ns, wbc_state(msg), msg)[1] == 0.002  # the first: one period
    return core, msg


def test_leaving_manipulate_cancels_the_arm_goal() -> None:
    core, msg = _commander("manipulate")
    t, state = msg.stamp_ns, wbc_state(msg)
    core.goals.accept(ArmGoalRequest(goal=Posture(name="ready")))
    core.start_goals(t)
    assert core.actions.active is not None
    core.set_mode(WbcMode(stamp_ns=t, mode="walk", cmd_vel_source="navigation"), t, state)
    (goal,) = core.actions.statuses()
    assert (goal.state, goal.reason) == ("cancelled", "mode manipulate -> walk")
    assert (
        core.mode == "walk" and core.reason == "mode manipulate -> walk (cmd_vel from navigation)"
    )
    assert core.actions.active is None


def test_a_mode_change_elsewhere_keeps_the_arm_goal_and_a_repeat_changes_nothing() -> None:
    core, msg = _commander("stand")
    t, state = msg.stamp_ns, wbc_state(msg)
    core.goals.accept(ArmGoalRequest(goal=Posture(name="ready")))
    core.start_goals(t)
    core.set_mode(WbcMode(stamp_ns=t, mode="walk", cmd_vel_source="mission"), t, state)
    assert core.actions.statuses()[0].state == "active" and core.arbiter.source == "mission"
    reason = core.reason
    core.set_mode(WbcMode(stamp_ns=t, mode="walk", cmd_vel_source="navigation"), t, state)
    assert core.arbiter.source == "navigation" and core.reason == reason  # the same mode


def test_goals_start_at_their_effective_tick_in_the_order_they_came() -> None:
    core, msg = _commander("manipulate")
    t = msg.stamp_ns
    for name, at in (("look", 6 * MS), ("ready", 4 * MS), ("stow", 4 * MS)):
        core.goals.accept(ArmGoalRequest(goal=Posture(name=name), effective_ns=at))  # type: ignore[arg-type]
    core.start_goals(t)
    assert core.actions.statuses() == []
    core.start_goals(t + 2 * MS)  # arm_2 then arm_3, which preempts it
    assert [(g.goal_id, g.state) for g in core.actions.statuses()] == [
        ("arm_2", "cancelled"),
        ("arm_3", "active"),
    ]
    core.start_goals(t + 4 * MS)
    assert [g.goal_id for g in core.actions.statuses()] == ["arm_2", "arm_3", "arm_1"]
