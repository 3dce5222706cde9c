"""The patrol's requests and step (`services.semantic_map.patrol_control`) around a fake
driver and odometry: refusals are typed, a start plans from the odometry's pose, the
floor plan's supports are fetched once, a tick steps only a running patrol."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from common.bus import RequestError, WaitTimeout
from common.config import SemanticMapSettings
from common.messages.semantic_map import PatrolRequest
from common.messages.world import SupportSurface
from services.semantic_map.mapper import MapParams, SemanticMap
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.patrol_control import PatrolControl

S = 1_000_000_000


class FakeDriver:
    def __init__(self) -> None:
        self.state, self.reason, self.route = "idle", "", None
        self.calls: list[tuple[str, Any]] = []

    @property
    def running(self) -> bool:
        return self.state == "running"

    def start(self, route: Any, yaw: float) -> None:
        self.state, self.route = "running", route
        self.calls.append(("start", yaw))

    def stop(self) -> None:
        self.state = "stopped"
        self.calls.append(("stop", None))

    def step(self, b: int, odom: Any) -> None:
        self.calls.append(("step", (b, odom)))

    def progress(self) -> tuple[int, int, float, int]:
        n = len(self.route.viewpoints) if self.route is not None else 0
        return 0, n, 0.0, 0


class FakeOdom:
    def __init__(self, odom: Any = None, arrives: bool = True) -> None:
        self.odom, self.arrives, self.waited = odom, arrives, 0

    def get(self) -> Any:
        return self.odom

    def at(self, _stamp_ns: int) -> Any:
        return self.odom

    def wait_stamp(self, _stamp_ns: int, _timeout_s: float) -> Any:
        self.waited += 1
        if not self.arrives:
            raise WaitTimeout("no odom")
        return self.odom


def _odom() -> SimpleNamespace:
    return SimpleNamespace(
        base_position_in_world=(0.0, 0.0, 0.3), base_orientation_xyzw=(0, 0, 0, 1)
    )


def _control(odom: FakeOdom, floor_plan: str = "none", world: Any = None) -> PatrolControl:
    cfg = SemanticMapSettings(floor_plan=floor_plan)  # type: ignore[arg-type]
    return PatrolControl(FakeDriver(), odom, cfg, world or (lambda _s: None))  # type: ignore[arg-type]


def _map() -> SemanticMap:
    occ = Occupancy(np.zeros((80, 80), np.uint8), 0.1, (-4.0, -4.0))
    return SemanticMap(MapParams(), occ, {})


def test_a_start_is_refused_without_odometry_or_while_a_patrol_runs() -> None:
    smap = _map()
    control = _control(FakeOdom(None))
    with pytest.raises(RequestError) as refused:
        control.request(PatrolRequest(action="start"), None, smap)
    assert refused.value.code == "unavailable"
    control = _control(FakeOdom(_odom()))
    status = control.request(PatrolRequest(action="start"), None, smap)
    assert status.state == "running" and status.waypoints > 0
    assert control.driver.calls == [("start", 0.0)]
    with pytest.raises(RequestError) as refused:
        control.request(PatrolRequest(action="start"), None, smap)
    assert refused.value.code == "busy"
    assert control.request(PatrolRequest(action="stop"), None, smap).state == "stopped"


def test_the_floor_plans_supports_are_fetched_once_and_only_with_the_world_plan() -> None:
    asked: list[float] = []
    surface = SupportSurface(
        id="table_1", centre_xy=(1.0, 1.0), half_extents=(0.5, 0.3), yaw=0.0, top_height=0.7
    )

    def world(wait_s: float) -> Any:
        asked.append(wait_s)
        return SimpleNamespace(surfaces=[surface])

    assert _control(FakeOdom(), "none", world).support_targets() is None
    control = _control(FakeOdom(), "world", world)
    first = control.support_targets()
    assert first is not None and first.shape[1] == 2
    assert control.support_targets() is first
    assert asked == [5.0]
    assert _control(FakeOdom(), "world", lambda _s: None).support_targets() is None


def test_a_tick_steps_only_a_running_patrol_on_the_odometry_of_the_tick() -> None:
    odom = FakeOdom(_odom(), arrives=False)
    control = _control(odom)
    assert control.step(S) is None and odom.waited == 0
    control.request(PatrolRequest(action="start"), None, _map())
    route = control.step(2 * S)  # the odom of the tick never comes: steps on the newest
    assert route is control.driver.route and odom.waited == 1
    assert control.driver.calls[-1] == ("step", (2 * S, odom.odom))
