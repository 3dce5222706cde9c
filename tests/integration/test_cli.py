"""The `dume` commands a user types, against real stacks."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.keys import WORLD_CLOCK
from common.messages.sim import Clock, Odom
from common.stack import free_port
from tests.conftest import HOLD_COMMANDER, StartStack, dume

pytestmark = pytest.mark.integration


def test_dume_world_prints_the_generated_world_as_json() -> None:
    out = dume("world", "--seed", "3")
    assert out.returncode == 0, out.stderr
    world = json.loads(out.stdout)
    assert world["seed"] == 3
    ids = [a["id"] for a in world["artifacts"]]
    assert "bottle_1" in ids and "bottle_2" in ids
    assert all(p["id"].startswith("person_") for p in world["people"])
    assert "occupancy" not in world  # only with --grid
    again = json.loads(dume("world", "--seed", "3").stdout)
    assert again == world


def test_a_request_without_a_mission_service_times_out_and_says_why(stack: StartStack) -> None:
    s = stack([])
    out = dume(
        "request", "bottle_1", "--to", "person_1", "--port", str(s.port), "--wait", "--timeout", "2"
    )
    assert out.returncode == 3
    last = json.loads(out.stdout.strip().splitlines()[-1])
    assert last["outcome"] == "timeout"
    assert "no mission service" in last["reason"]


def test_commands_say_when_no_stack_answers() -> None:
    out = dume("status", "--port", str(free_port()), timeout=30)
    assert out.returncode == 1
    assert "no dume stack answers" in out.stderr


def test_a_bad_setting_is_refused_with_its_key() -> None:
    out = dume("status", "--set", "sim.wrold=1", timeout=30)
    assert out.returncode == 2
    assert "wrold" in out.stderr


def test_the_realtime_mode_runs_the_robot_on_the_wall_clock(stack: StartStack) -> None:
    s = stack(
        ["sim", "hold"],
        *HOLD_COMMANDER,
        'sim.world="small"',
        "sim.cameras=[]",
        'time.mode="realtime"',
    )
    clock = s.bus.latest(WORLD_CLOCK, Clock)
    odom = s.bus.latest(s.keys.odom, Odom)
    c = clock.wait(lambda c: c.stamp_ns >= 1_500_000_000, 60)
    assert c.mode == "realtime"
    o = odom.wait(lambda o: o.stamp_ns >= 1_000_000_000, 10)
    assert abs(o.base_position_in_world[2] - 0.525) < 0.02
    assert not o.watchdog


def test_a_run_records_the_world_the_robot_and_both_cameras(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(
        ["sim", "hold"], *HOLD_COMMANDER, 'sim.world="small"', "sim.duration_s=1.2", record=True
    )
    clock = s.bus.latest(WORLD_CLOCK, Clock)
    clock.wait(lambda c: c.stamp_ns >= 1_100_000_000, 120)
    time.sleep(0.5)
    s.stop()
    runs = list((tmp_path / "recordings").iterdir())
    assert len(runs) == 1
    rrd = runs[0] / "sim.rrd"
    assert rrd.exists() and (runs[0] / "hold.rrd").exists()
    stats = subprocess.run(
        [str(Path(sys.executable).with_name("rerun")), "rrd", "stats", str(rrd)],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    for entity in (
        "/world/bodies/trunk",
        "/world/bodies/bottle_1",
        "/world/bodies/person_1",
        "/camera/camera_head/rgb",
        "/camera/camera_wrist/rgb",
        "/camera/camera_head/depth",
        "/plots/sim/base_height_m",
    ):
        assert entity in stats, entity
