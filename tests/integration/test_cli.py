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
from deploy.stack import free_port
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


def test_a_request_without_a_mission_service_says_so_instead_of_waiting(stack: StartStack) -> None:
    s = stack([])
    out = dume(
        "request",
        "bottle_1",
        "--to",
        "person_1",
        "--port",
        str(s.port),
        "--wait",
        "--timeout",
        "600",
    )
    assert out.returncode == 1 and out.stdout == ""  # nothing was sent
    assert out.stderr.startswith("dume: the mission service is not running (`dume status`")
    status = dume("status", "--port", str(s.port))
    assert status.returncode == 1  # a stack missing services is not well: it says which
    assert "mission" in json.loads(status.stdout)["missing"]


def test_commands_say_when_no_stack_answers_in_one_line_with_a_hint() -> None:
    port = str(free_port())
    for args in (("status",), ("request", "bottle_1", "--to", "person_1"), ("map",)):
        out = dume(*args, "--port", port, timeout=30)
        assert out.returncode == 1, args
        (line,) = out.stderr.strip().splitlines()
        assert line.startswith(f"dume: no dume stack on tcp/127.0.0.1:{port}"), line
        assert "`dume up`" in line and ".rs" not in line


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (("world", "--seed", "-1"), "seeds are 0 or more"),
        (("status", "--port", "0"), "0 is not a port (1-65535)"),
        (("map", "--import", "/nonexistent/map.json"), "map file /nonexistent/map.json does not"),
        (("logs", "--run", "no-such-run"), "no run 'no-such-run'"),
        (("up", "--map", "/nonexistent/map.json"), "no map file /nonexistent/map.json"),
    ],
)
def test_argument_and_file_errors_are_one_line_with_the_cause(
    args: tuple[str, ...], said: str
) -> None:
    out = dume(*args, timeout=30)
    assert out.returncode in (1, 2)
    assert said in out.stderr.strip().splitlines()[-1]
    assert "Traceback" not in out.stderr


def test_version_and_help_keep_the_usage() -> None:
    assert dume("--version").stdout.startswith("dume ")
    help_ = dume("--help").stdout
    assert "dume request OBJECT --to PERSON" in help_ and "dume logs" in help_


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
        "/plots/truth/base_height_m",
    ):
        assert entity in stats, entity


DEMO_KEYS = {
    "outcome", "reason", "sim_time_s", "wall_time_s", "rtf", "locomotion", "recording", "digest"
}  # fmt: skip


def _last_json(out: subprocess.CompletedProcess[str]) -> dict[str, object]:
    assert out.stdout.strip(), out.stderr[-3000:]
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def test_the_demo_refuses_an_object_the_map_does_not_hold_and_stops_its_stack() -> None:
    """From the small world's saved map (explored from nothing, `deploy/maps/`): the stack
    comes up on it with no floor plan, the robot localizing on its grid, and the demo
    refuses an id the map does not hold, naming the ones it does."""
    out = dume("demo", "--world", "small", "--map", "saved", "--object", "bottle_9", timeout=600)
    assert out.returncode == 1
    line = _last_json(out)
    assert set(line) == DEMO_KEYS
    assert line["outcome"] == "failed"
    assert "bottle_9" in str(line["reason"]) and "bottle_1" in str(line["reason"])
    assert "the saved map deploy/maps/small-seed-0.json" in out.stderr


@pytest.mark.slow
def test_the_truth_ablation_demo_names_the_truths_entities() -> None:
    out = dume("demo", "--world", "small", "--map", "truth", "--object", "bottle_9", timeout=600)
    assert out.returncode == 1
    assert "seed-from-world (truth + noise: the ablation)" in out.stderr
    assert "bottle_9" in str(_last_json(out)["reason"])
