"""The lockstep rate of a stack: sim ticks per wall second, from the clock's arrivals."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from common.config import Overrides, merged
from common.keys import CAMERAS, WORLD_CLOCK
from common.messages.sim import CameraFrame, Clock
from deploy.stack import ProcessStack


def commander(name: str, period_s: float) -> dict[str, Any]:
    """Settings that make `name` the only lockstep participant, the joint commander."""
    return {
        "time.participants": {name: {"role": "command", "period_s": period_s, "latency_s": 0.0}}
    }


def lockstep_rate(
    services: Sequence[str], settings: Overrides, sim_s: float, cameras: bool
) -> float:
    """Ticks per wall second over `sim_s` of sim time in the small world.

    With `cameras`, this process subscribes to both cameras, as perception would: the
    sim renders only the cameras someone watches (or records).
    """
    all_settings = merged(
        {"sim.world": "small", "recording.enabled": False, "sim.duration_s": sim_s + 2.0},
        {} if cameras else {"sim.cameras": []},
        settings,
    )
    with ProcessStack(list(services), all_settings) as stack:
        watchers = (
            [stack.bus.latest(stack.keys.camera_rgbd(c), CameraFrame) for c in CAMERAS]
            if cameras
            else []
        )
        clock = stack.bus.latest(WORLD_CLOCK, Clock)
        first = clock.wait(lambda c: c.stamp_ns >= 500_000_000, 120.0)
        t0 = time.perf_counter()
        last = clock.wait(lambda c: c.stamp_ns >= first.stamp_ns + int(sim_s * 1e9), 600.0)
        wall = time.perf_counter() - t0
        if cameras and not all(w.received for w in watchers):
            raise RuntimeError("the cameras were not rendered: the rate would be wrong")
    return (last.tick - first.tick) / wall
