"""Navigation over a real lockstep stack with the whole-body controller (dynamic gait).

The map is the semantic map's (`navigation.map_source="map"`, seeded from the world into
the test's folder), so its occupancy and people queryables are exercised. The WBC starts
in `walk` obeying navigation's cmd_vel. What is checked comes from the sim's truth
(odom, contact events, the people commands the test itself sends).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from bench import nav_person
from common.clients import NavClient
from common.config import PeopleSettings
from common.geometry import yaw_of_quat_xyzw
from common.keys import WORLD_EVENTS
from common.messages.navigation import (
    NavCancel,
    NavStatus,
    PoseGoal,
)
from common.messages.sim import Odom, RobotContact, WorldEvents
from deploy.stack import ProcessStack
from services.navigation.people import separation_params
from services.navigation.separation import protective_distance
from tests.conftest import StartStack

pytestmark = pytest.mark.integration

NAV = (
    'sim.world="small"',
    "sim.world_seed=1",
    'sim.cameras=["camera_head"]',
    "time.participants={}",
    'time.participants.wbc.role="command"',
    "time.participants.wbc.period_s=0.002",
    "time.participants.wbc.latency_s=0.0",
    'time.participants.navigation.role="periodic"',
    "time.participants.navigation.period_s=0.05",
    "time.participants.navigation.latency_s=0.05",
    'time.participants.semantic_map.role="periodic"',
    "time.participants.semantic_map.period_s=0.1",
    "time.participants.semantic_map.latency_s=0.1",
    'semantic_map.start="seed-from-world"',
    "semantic_map.reset=true",
    'semantic_map.name="nav_test"',
    'navigation.map_source="map"',
    'wbc.initial_mode="walk"',
)
NAV_SERVICES = ["sim", "wbc", "semantic_map", "navigation"]


def _map_dir(tmp_path: Path) -> str:
    return f'semantic_map.dir="{tmp_path / "map"}"'


def _send(s: ProcessStack, goal: PoseGoal) -> str:
    """The goal's id, sent once (the first often before navigation has its map: it waits)."""
    return NavClient(s.bus, s.keys, 10.0).send(goal)


def _wait_done(status: object, goal_id: str, timeout_s: float) -> NavStatus:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        st = status.get()  # type: ignore[attr-defined]
        if st is not None and st.goal_id == goal_id and st.state not in ("active", "idle"):
            return st
        time.sleep(0.2)
    raise AssertionError(f"goal {goal_id} not done within {timeout_s} s: {status.get()}")  # type: ignore[attr-defined]


def _pose(odom: Odom) -> tuple[float, float, float]:
    p = odom.base_position_in_world
    return p[0], p[1], yaw_of_quat_xyzw(odom.base_orientation_xyzw)


@pytest.mark.slow  # about 2 min of walking: out of the quick loop
def test_three_goals_in_the_small_world_are_reached_without_touching_obstacles(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(NAV_SERVICES, *NAV, _map_dir(tmp_path))
    status = s.bus.latest(s.keys.nav_status, NavStatus)
    odom = s.bus.latest(s.keys.odom, Odom)
    events = s.bus.fifo(WORLD_EVENTS, WorldEvents)
    goals = [PoseGoal(x=0.3, y=1.8, yaw=0.0), PoseGoal(x=-2.0, y=-2.0, yaw=math.pi / 2),
             PoseGoal(x=0.6, y=-0.6, yaw=0.0)]  # fmt: skip
    for goal in goals:
        goal_id = _send(s, goal)
        done = _wait_done(status, goal_id, 900.0)
        assert done.state == "succeeded", done
        x, y, yaw = _pose(odom.get())  # type: ignore[arg-type]
        assert math.hypot(x - goal.x, y - goal.y) <= goal.position_tolerance_m + 0.05
        assert abs(math.remainder(yaw - goal.yaw, math.tau)) <= goal.yaw_tolerance_rad + 0.05
    contacts = [
        e for w in events.drain() for e in w.events
        if isinstance(e, RobotContact) and e.other != "floor"
    ]  # fmt: skip
    assert contacts == []


def test_a_cancel_brings_the_base_to_rest_within_half_a_second(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(NAV_SERVICES, *NAV, _map_dir(tmp_path))
    status = s.bus.latest(s.keys.nav_status, NavStatus)
    odom = s.bus.fifo(s.keys.odom, Odom, maxlen=100_000)
    cancel = s.bus.publisher(s.keys.nav_cancel, NavCancel)
    goal_id = _send(s, PoseGoal(x=0.5, y=2.3, yaw=0.0))
    samples: list[Odom] = []
    deadline = time.monotonic() + 600.0
    while time.monotonic() < deadline:  # walking at speed
        msg = odom.pop(timeout_s=1.0)
        if msg is not None:
            samples.append(msg)
            if math.hypot(*msg.base_linear_velocity_in_world[:2]) > 0.3:
                break
    cancel.put(NavCancel(goal_id=goal_id, reason="test"))
    done = _wait_done(status, goal_id, 120.0)
    assert done.state == "cancelled"
    after = [m for m in (odom.pop(timeout_s=5.0) for _ in range(200)) if m is not None]
    cancelled_at = done.stamp_ns
    rest = next(
        m.stamp_ns for m in after
        if m.stamp_ns >= cancelled_at and math.hypot(*m.base_linear_velocity_in_world[:2]) < 0.05
    )  # fmt: skip
    assert (rest - cancelled_at) / 1e9 <= 0.5


# -- a person stepping into the path ----------------------------------------------------

HALL_PERSON = (
    *NAV,
    nav_person.SETTINGS,
    'time.participants.perception.role="periodic"',
    "time.participants.perception.period_s=0.1",
    "time.participants.perception.latency_s=0.1",
)


@pytest.mark.slow
def test_a_person_stepping_into_the_path_slows_and_stops_the_robot_which_then_goes_on(
    stack: StartStack, tmp_path: Path
) -> None:
    """The person steps into the path 4.5 m ahead and stands there (`bench.nav_person`):
    the robot slows within 2 m (after a 0.5 s reaction time), and either walks round them
    (the plan avoids people and what the head camera's depth shows) or stops short of
    them and goes on once they leave; it never moves towards them inside the protective
    separation of ISO/TS 15066 (judged from truth), nor comes within its value at rest for
    someone standing; it reaches its goal."""
    services = ["sim", "wbc", "perception", "semantic_map", "navigation"]
    s = stack(services, *HALL_PERSON, _map_dir(tmp_path))
    f = nav_person.person_scenario(s, "step_in")
    assert f.t_in_s > 0, f
    assert f.state == "succeeded", f
    assert f.violations == 0, f
    sep = separation_params(PeopleSettings())
    assert f.closest_m >= protective_distance(0.0, 0.0, sep), f
    assert f.fastest_near_mps <= 0.3, f
    # It stopped for them, or its plan took it round them (6 m straight ahead otherwise).
    assert f.slowest_near_mps < 0.05 or f.walked_m > 6.3, f
    assert not f.t_out_s or f.moving_after_out, f
    assert f.contacts == {}, f
