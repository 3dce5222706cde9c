"""The mission service over real Zenoh, in lockstep: typed refusals, cancel, dependencies.

The semantic map is seeded from the small world's truth (`bottle_1`, `person_1`), so the
mission can check requests against it.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest

from bench.eval.judge import MissionRecord
from bench.eval.run import watch_mission
from common.keys import WORLD_CLOCK
from common.messages.mission import MissionCancel, MissionRequest, MissionStatus
from common.messages.navigation import NavStatus
from common.messages.sim import Clock
from common.messages.wbc import WbcStatus
from deploy.stack import ProcessStack
from tests.conftest import HOLD_COMMANDER, StartStack
from tests.integration.test_wbc_stack import WBC

pytestmark = pytest.mark.integration

MISSION = (
    'time.participants.mission.role="periodic"',
    "time.participants.mission.period_s=0.05",
    "time.participants.mission.latency_s=0.05",
)
MAP = (
    'time.participants.semantic_map.role="periodic"',
    "time.participants.semantic_map.period_s=0.1",
    "time.participants.semantic_map.latency_s=0.1",
    'semantic_map.start="seed-from-world"',
    'sim.world="small"',
)


class User:
    """A person with a Zenoh client: puts JSON requests, reads every status in order."""

    def __init__(self, s: ProcessStack) -> None:
        self.s = s
        self.statuses = s.bus.fifo(s.keys.mission_status, MissionStatus, maxlen=100_000)
        self.seen: list[MissionStatus] = []
        self._req = s.bus.publisher(s.keys.mission_request, MissionRequest)
        self._cancel = s.bus.publisher(s.keys.mission_cancel, MissionCancel)

    def request(self, payload: bytes | dict[str, object]) -> None:
        raw = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        self._req.put_raw(raw)

    def cancel(self, request_id: str, reason: str = "test") -> None:
        self._cancel.put_raw(json.dumps({"request_id": request_id, "reason": reason}).encode())

    def wait(self, request_id: str, states: set[str], timeout_s: float) -> MissionStatus:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            st = self.statuses.pop(timeout_s=0.5)
            if st is None:
                continue
            self.seen.append(st)
            if st.request_id == request_id and st.state in states:
                return st
        seen = [(m.request_id, m.state, m.reason) for m in self.seen[-20:]]
        raise AssertionError(f"no {states} for {request_id!r} in {timeout_s} s; last: {seen}")


def _no_controller_stack(stack: StartStack, tmp_path: Path) -> ProcessStack:
    """The map and the mission with a stand-hold: a mission stays running (no mode)."""
    return stack(
        ["sim", "hold", "semantic_map", "mission"],
        *HOLD_COMMANDER, *MAP, *MISSION,
        "sim.cameras=[]",
        f'semantic_map.dir="{tmp_path / "map"}"',
        "mission.mode_timeout_s=100000.0",
    )  # fmt: skip


def test_bad_requests_get_typed_rejections_and_the_service_stays_up(
    stack: StartStack, tmp_path: Path
) -> None:
    s = _no_controller_stack(stack, tmp_path)
    user = User(s)
    cases: list[tuple[bytes | dict[str, object], str, str]] = [
        (b"{not json", "", "malformed"),
        ({"request_id": "r-types", "object": 7, "person": "person_1"}, "r-types", "malformed"),
        ({"request_id": "r-missing", "object": "bottle_1"}, "r-missing", "malformed"),
        ({"request_id": "r-obj", "object": "bottle_9", "person": "person_1"}, "r-obj",
         "unknown_object"),
        ({"request_id": "r-class", "object": "forklift", "person": "person_1"}, "r-class",
         "unknown_object"),
        ({"request_id": "r-person", "object": "bottle_1", "person": "person_7"}, "r-person",
         "unknown_person"),
    ]  # fmt: skip
    for payload, request_id, reason in cases:
        user.request(payload)
        st = user.wait(request_id, {"rejected"}, 60.0)
        assert st.reason == reason, st
        assert st.detail
    user.request({"request_id": "r-ok", "object": "bottle", "person": "person_1"})
    assert user.wait("r-ok", {"accepted"}, 60.0).reason == ""
    user.wait("r-ok", {"running"}, 60.0)
    user.request({"request_id": "r-second", "object": "bottle_1", "person": "person_1"})
    busy = user.wait("r-second", {"rejected"}, 60.0)
    assert busy.reason == "busy" and "r-ok" in busy.detail
    assert s.procs["mission"].poll() is None
    assert "mission" in s.alive()
    user.cancel("r-ok")
    assert user.wait("r-ok", {"cancelled"}, 60.0).reason == "cancelled"


def test_a_dependency_that_dies_mid_mission_is_said_at_once_then_fails_it(
    stack: StartStack, tmp_path: Path
) -> None:
    """Killed, the map is noticed within a second of sim time (the status says the
    request holds for it), and not back as the same process within `HOLD_S` the request
    fails `dependency_lost`."""
    s = _no_controller_stack(stack, tmp_path)
    user = User(s)
    clock = s.bus.latest(WORLD_CLOCK, Clock)
    user.request({"request_id": "r1", "object": "bottle_1", "person": "person_1"})
    user.wait("r1", {"running"}, 60.0)
    before = clock.wait(lambda _c: True, 10.0).stamp_ns
    s.kill("semantic_map")
    done = user.wait("r1", {"failed", "cancelled", "succeeded"}, 60.0)
    assert (done.state, done.reason) == ("failed", "dependency_lost"), done
    assert done.detail == "semantic_map is gone"
    (held, *_) = [m for m in user.seen if m.detail.startswith("holding: semantic_map not heard")]
    assert held.request_id == "r1" and held.state == "running"
    assert held.stamp_ns - before <= 1_000_000_000, "the mission waited to notice the dead"
    # A new request without the map is refused at once, not started.
    user.request({"request_id": "r2", "object": "bottle_1", "person": "person_1"})
    refused = user.wait("r2", {"rejected", "accepted"}, 60.0)
    assert (refused.state, refused.reason) == ("rejected", "unavailable"), refused
    assert "semantic_map" in refused.detail
    assert s.procs["mission"].poll() is None


def test_a_sim_that_dies_mid_mission_fails_it_without_waiting_for_a_tick(
    stack: StartStack, tmp_path: Path
) -> None:
    """No clock comes from a dead world: the mission notices it without a tick."""
    s = _no_controller_stack(stack, tmp_path)
    user = User(s)
    user.request({"request_id": "r1", "object": "bottle_1", "person": "person_1"})
    running = user.wait("r1", {"running"}, 60.0)
    s.kill("sim")
    done = user.wait("r1", {"failed", "cancelled", "succeeded"}, 30.0)  # not left running
    assert (done.state, done.reason) == ("failed", "dependency_lost"), done
    assert done.detail.startswith("sim is gone: the world stopped at t="), done.detail
    assert done.stamp_ns >= running.stamp_ns
    assert s.procs["mission"].poll() is None


def test_a_wbc_that_dies_mid_mission_fails_it_with_the_robot_held(
    stack: StartStack, tmp_path: Path
) -> None:
    """The WBC is the robot's legs: killed mid-request, the lockstep clock stops (the sim
    waits for its command, its watchdog holds the joints) and the mission fails the
    request `dependency_lost` at once, without a tick; it is not left running."""
    s = stack(
        ["sim", "wbc", "semantic_map", "mission"],
        *WBC, *MAP, *MISSION,
        "sim.cameras=[]",
        f'semantic_map.dir="{tmp_path / "map"}"',
        "mission.mode_timeout_s=100000.0",
    )  # fmt: skip
    user = User(s)
    user.request({"request_id": "r1", "object": "bottle_1", "person": "person_1"})
    running = user.wait("r1", {"running"}, 120.0)
    s.kill("wbc")
    done = user.wait("r1", {"failed", "cancelled", "succeeded"}, 30.0)
    assert (done.state, done.reason) == ("failed", "dependency_lost"), done
    assert done.detail.startswith("wbc is gone"), done.detail
    assert done.stamp_ns >= running.stamp_ns
    assert s.procs["mission"].poll() is None and s.procs["sim"].poll() is None


def test_a_watch_whose_mission_dies_ends_with_dependency_lost_instead_of_waiting(
    stack: StartStack, tmp_path: Path
) -> None:
    s = _no_controller_stack(stack, tmp_path)
    user = User(s)
    request = MissionRequest(request_id="r1", object="bottle_1", person="person_1")
    records: list[MissionRecord] = []
    watch = threading.Thread(
        target=lambda: records.append(watch_mission(s.bus, s.keys, request, timeout_s=3600.0))
    )
    watch.start()
    user.wait("r1", {"running"}, 60.0)
    s.kill("mission")
    watch.join(timeout=120.0)
    assert not watch.is_alive(), "the watch kept waiting for a dead mission"
    (record,) = records
    assert record.ended == "dependency_lost: mission is gone", record.ended
    assert record.changes[-1].state == "running"
    # Started again, the mission says it holds no request, so the client can send it again.
    s.spawn("mission")
    fresh = user.wait("", {"idle"}, 120.0)
    assert fresh.stamp_ns > 0 and fresh.detail.startswith("mission started at t="), fresh
    user.request({"request_id": "r2", "object": "bottle_1", "person": "person_1"})
    assert user.wait("r2", {"accepted", "rejected"}, 60.0).state == "accepted"


def test_a_cancel_mid_navigation_ends_cancelled_with_the_nav_goal_cancelled(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(
        ["sim", "wbc", "semantic_map", "navigation", "mission"],
        *MAP, *MISSION,
        'sim.cameras=["camera_head"]',
        'semantic_map.cameras=["camera_head"]',
        f'semantic_map.dir="{tmp_path / "map"}"',
    )  # fmt: skip
    user = User(s)
    nav = s.bus.latest(s.keys.nav_status, NavStatus, history=64)
    wbc = s.bus.latest(s.keys.wbc_status, WbcStatus)
    user.request({"request_id": "r1", "object": "bottle_1", "person": "person_1"})
    user.wait("r1", {"accepted"}, 120.0)
    deadline = time.monotonic() + 300.0
    goal = None
    while time.monotonic() < deadline:  # walking toward the bottle
        st = nav.get()
        if st is not None and st.state == "active" and st.progress > 0.05:
            goal = st.goal_id
            break
        time.sleep(0.2)
    assert goal is not None, f"navigation never got going: {nav.get()}"
    user.cancel("r1", "changed my mind")
    done = user.wait("r1", {"cancelled", "failed", "succeeded"}, 120.0)
    assert (done.state, done.reason) == ("cancelled", "cancelled"), done
    end = nav.wait(lambda m: m.goal_id == goal and m.state != "active", 60.0)
    assert end.state == "cancelled"
    at_rest = wbc.wait(lambda m: m.mode == "stand", 60.0)
    assert at_rest.cmd_vel_source == "navigation"
    assert s.procs["mission"].poll() is None
