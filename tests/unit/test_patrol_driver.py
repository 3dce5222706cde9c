"""The patrol driver's arm phase on a fake bus: the arm goes to `look` before the first
walk goal, a WBC that cannot take it yet is asked again, one that does not answer leaves
the patrol to the head camera, and the end stows the arm."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from common.bus import NoReply, RemoteError
from common.config import load_config
from common.keys import RobotKeys
from common.messages.errors import ErrorReply
from common.messages.navigation import NavGoalReply, NavGoalRequest, NavStatus
from common.messages.sim import Odom
from common.messages.wbc import ArmGoalReply, GoalStatus, WbcMode, WbcStatus
from services.semantic_map.patrol import Route
from services.semantic_map.patrol_driver import ARM_WAIT_S, PatrolDriver

KEYS = RobotKeys()
S = 1_000_000_000


class _Latest:
    def __init__(self) -> None:
        self.value: Any = None

    def get(self) -> Any:
        return self.value

    def at(self, _stamp_ns: int) -> Any:
        return self.value


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[Any] = []

    def put(self, msg: Any) -> None:
        self.sent.append(msg)


class FakeBus:
    """Publishers record, `latest` values are set by the test, queries go to `answer`."""

    def __init__(self) -> None:
        self.publishers: dict[str, _Publisher] = {}
        self.latests: dict[str, _Latest] = {}
        self.queries: list[tuple[str, Any]] = []
        self.arm_answers: list[Any] = []

    def publisher(self, key: str, _type: type, _kind: str) -> _Publisher:
        return self.publishers.setdefault(key, _Publisher())

    def latest(self, key: str, _type: type, history: int = 1) -> _Latest:
        return self.latests.setdefault(key, _Latest())

    def query(self, key: str, req: Any, _reply: type, _timeout: float) -> Any:
        self.queries.append((key, req))
        if key == KEYS.arm_goal:
            answer = self.arm_answers.pop(0) if self.arm_answers else ArmGoalReply(True, "arm_9")
            if isinstance(answer, Exception):
                raise answer
            return answer
        assert isinstance(req, NavGoalRequest)
        return NavGoalReply(accepted=True, goal_id=f"nav_{len(self.queries)}")

    def arm_requests(self) -> list[str]:
        return [r.goal.name for k, r in self.queries if k == KEYS.arm_goal]

    def nav_requests(self) -> int:
        return sum(k == KEYS.nav_goal for k, _r in self.queries)


def _wbc(goal_id: str, state: str) -> WbcStatus:
    return WbcStatus(
        stamp_ns=0, mode="walk", cmd_vel_source="navigation",
        goals=[GoalStatus(goal_id=goal_id, kind="posture", state=state)],  # type: ignore[arg-type]
        base_error_m=0.0, gripper_error_m=0.0, gripper_error_rad=0.0, qp_time_us=0.0,
        qp_failures=0, contacts=(True, True, True, True), gripper_angle=0.0,
        gripper_effort=0.0, held=False, gripper_wrench=(0.0,) * 6,
    )  # fmt: skip


def _odom() -> Odom:
    return Odom(0, (0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0), (0.0,) * 3, (0.0,) * 3, 0.0, 0.0)


def _driver(posture: str = "look") -> tuple[FakeBus, PatrolDriver]:
    bus = FakeBus()
    cfg = load_config([f'semantic_map.patrol_arm_posture="{posture}"']).semantic_map
    d = PatrolDriver(bus, KEYS, cfg, "semantic_map", "navigation")  # type: ignore[arg-type]
    route = Route([np.array([2.0, 0.0])], [np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])])
    d.start(route, 0.0)
    return bus, d


def test_the_arm_reaches_look_before_the_first_walk_goal() -> None:
    bus, d = _driver()
    d.step(1 * S, _odom())
    assert bus.arm_requests() == ["look"] and bus.nav_requests() == 0
    modes = bus.publishers[KEYS.wbc_mode].sent
    assert [m.mode for m in modes] == ["walk"]
    d.step(2 * S, _odom())  # the WBC has not listed the goal yet: still waiting
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "active")
    d.step(3 * S, _odom())
    assert bus.nav_requests() == 0
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "succeeded")
    assert not d.arm_up
    d.step(4 * S, _odom())
    assert bus.nav_requests() == 1 and bus.arm_requests() == ["look"]
    assert d.arm_up  # the map fuses the wrist camera from now on
    d.stop()
    d.step(5 * S, _odom())
    assert not d.arm_up


def test_a_wbc_not_ready_is_asked_again_and_a_failed_posture_walks_on() -> None:
    bus, d = _driver()
    bus.arm_answers = [RemoteError(KEYS.arm_goal, ErrorReply(code="unavailable", message="damp"))]
    d.step(1 * S, _odom())
    d.step(2 * S, _odom())
    assert bus.arm_requests() == ["look", "look"] and bus.nav_requests() == 0
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "failed")
    d.step(3 * S, _odom())
    assert bus.nav_requests() == 1


@pytest.mark.parametrize("silent", [True, False])
def test_no_wbc_or_no_progress_leaves_the_patrol_to_the_head_camera(silent: bool) -> None:
    bus, d = _driver()
    if silent:
        bus.arm_answers = [NoReply("nobody")]
        d.step(1 * S, _odom())
        assert bus.nav_requests() == 1  # at once: no WBC to wait for
    else:
        d.step(1 * S, _odom())
        d.step(1 * S + int(ARM_WAIT_S * S) - 1, _odom())
        assert bus.nav_requests() == 0
        d.step(2 * S + int(ARM_WAIT_S * S), _odom())
        assert bus.nav_requests() == 1
    assert d.running


def test_the_end_stows_the_arm_and_stands() -> None:
    bus, d = _driver()
    d.step(1 * S, _odom())
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "succeeded")
    d.step(2 * S, _odom())
    d.stop()
    d.step(3 * S, _odom())
    assert d.state == "stopped"
    assert bus.arm_requests() == ["look", "stow"]
    assert isinstance(bus.publishers[KEYS.wbc_mode].sent[-1], WbcMode)
    assert bus.publishers[KEYS.wbc_mode].sent[-1].mode == "stand"


def test_a_stowed_patrol_sends_no_second_stow() -> None:
    bus, d = _driver("stow")
    d.step(1 * S, _odom())
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "succeeded")
    d.step(2 * S, _odom())
    d.stop()
    d.step(3 * S, _odom())
    assert bus.arm_requests() == ["stow"]


def test_after_the_arm_navigation_status_moves_the_patrol_on() -> None:
    bus, d = _driver()
    d.step(1 * S, _odom())
    bus.latests[KEYS.wbc_status].value = _wbc("arm_9", "succeeded")
    d.step(2 * S, _odom())
    nav_id = f"nav_{len(bus.queries)}"  # the walk goal's id (the fake numbers them)
    d.step(3 * S, _odom())
    assert bus.nav_requests() == 1  # the walk goal is still on its way
    bus.latests[KEYS.nav_status].value = NavStatus(
        stamp_ns=3 * S, goal_id=nav_id, state="succeeded"
    )
    d.step(4 * S, _odom())
    assert bus.nav_requests() == 2  # the first turn of the look-around
