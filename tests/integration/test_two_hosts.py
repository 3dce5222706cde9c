"""A stack split over two hosts (`zenoh.side`), on real routers linked by mutual TLS:
a user at the station reaches the robot's mission but never its velocity, mode or
joints; a router with the right certificate but not the link's secret, or with a
certificate of another authority, carries nothing to the robot; and the small world's
bring-me succeeds with the map on the station (slow)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import msgspec
import pytest

from bench.trial_fetch import run_fetch
from common.access import USER
from common.bus import Bus, open_session
from common.certs import make_certs
from common.config import Config
from common.messages.mission import MissionRequest
from common.messages.wbc import CmdVel, WbcMode
from deploy.stack import ProcessStack, free_port
from tests.conftest import StartStack

pytestmark = pytest.mark.integration


def _hosts(stack: StartStack, tmp_path: Path) -> tuple[ProcessStack, ProcessStack]:
    """The two routers of a split stack (no services): the robot's, and the station's
    linked to it."""
    certs = tmp_path / "certs"
    make_certs(certs)
    link: dict[str, Any] = {"zenoh.certs": str(certs), "zenoh.link_port": free_port()}
    robot = stack([], link | {"zenoh.side": "robot"})
    station = stack([], link | {"zenoh.side": "station"})
    return robot, station


def _rogue_router(config: Config, certs: Path, port: int) -> Any:
    """A station's router on `port` whose link credentials are `certs`."""
    z = msgspec.structs.replace(config.zenoh, certs=str(certs), port=port)
    return open_session(msgspec.structs.replace(config, zenoh=z), "router")


def _puts(bus: Bus, keys: Any, request_id: str) -> None:
    """A user's request, and what a rogue would move the robot with."""
    bus.publisher(keys.mission_request, MissionRequest).put(
        MissionRequest(request_id=request_id, object="bottle_1", person="person_1")
    )
    bus.publisher(keys.wbc_mode, WbcMode).put(WbcMode(stamp_ns=0, mode="damp"))
    bus.publisher(keys.cmd_vel, CmdVel).put(CmdVel(stamp_ns=0, vx=0.5, vy=0.0, wz=0.0, source="x"))


def _arrived(fifo: Any, until_s: float, want: str | None = None) -> list[Any]:
    got: list[Any] = []
    deadline = time.monotonic() + until_s
    while time.monotonic() < deadline:
        got += list(fifo.drain())
        if want is not None and any(getattr(m, "request_id", "") == want for m in got):
            break
        time.sleep(0.05)
    return got


def test_a_user_at_the_station_reaches_the_mission_and_nothing_that_moves_the_robot(
    stack: StartStack, tmp_path: Path
) -> None:
    robot, station = _hosts(stack, tmp_path)
    keys = robot.keys
    requests = robot.bus.fifo(keys.mission_request, MissionRequest)
    commands = [robot.bus.fifo(keys.cmd_vel, CmdVel), robot.bus.fifo(keys.wbc_mode, WbcMode)]
    with Bus.open(station.config, user=USER) as user:
        got: list[Any] = []
        for k in range(40):  # until the link is up and the declarations crossed it
            _puts(user, keys, f"station-{k}")
            got += _arrived(requests, 0.25)
            if got:
                break
        assert got, "the user's request never crossed the link"
        # the station's own tools are not trusted on the robot: the link carries what the
        # station's services and its users may, and no more
        _puts(station.bus, keys, "station-tool")
        time.sleep(1.0)
    assert [len(list(c.drain())) for c in commands] == [0, 0]


@pytest.mark.parametrize("forged", ["nothing", "secret", "authority"])
def test_a_router_without_the_links_secret_or_certificate_carries_nothing(
    stack: StartStack, tmp_path: Path, forged: str
) -> None:
    """A second station router on the link: with copies of the real station's files it
    carries a user's request (the control), with a guessed secret or a certificate of
    another authority nothing."""
    robot, station = _hosts(stack, tmp_path)
    keys = robot.keys
    requests = robot.bus.fifo(keys.mission_request, MissionRequest)
    real = Path(station.config.zenoh.certs)
    wrong = tmp_path / "forged"
    make_certs(wrong)  # another authority, its certificates, its secret
    if forged != "authority":
        for name in ("ca.pem", "station.pem", "station-key.pem"):
            (wrong / name).write_bytes((real / name).read_bytes())
    if forged != "secret":
        (wrong / "link.secret").write_text((real / "link.secret").read_text())
    port = free_port()
    got: list[Any] = []
    with _rogue_router(station.config, wrong, port):
        other = msgspec.structs.replace(station.config.zenoh, port=port)
        config = msgspec.structs.replace(station.config, zenoh=other)
        with Bus.open(config, user=USER) as user:
            for k in range(40 if forged == "nothing" else 12):
                _puts(user, keys, f"second-{k}")
                got += _arrived(requests, 0.25)
                if got:
                    break
    got += _arrived(requests, 1.0)
    carried = [m for m in got if m.request_id.startswith("second-")]
    assert bool(carried) == (forged == "nothing"), (forged, len(carried))


@pytest.mark.slow
def test_the_small_worlds_bring_me_succeeds_with_the_map_on_the_station(tmp_path: Path) -> None:
    certs = tmp_path / "certs"
    make_certs(certs)
    out = run_fetch(seed=1, hosts={"zenoh.certs": str(certs), "zenoh.link_port": free_port()})
    assert out["success"] and out["handed_over"], out["mission"]
    assert out["held_after_pick"] and out["contacts_static"] == 0
