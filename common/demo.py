"""`dume demo`: start a stack under supervisord, run the job, stop, print one JSON line.

Until the mission service exists the job is the simulator's and the whole-body
controller's: the robot stands in the generated world for `--duration` seconds of sim time, every
camera and the world go to the run's recording, and the outcome says whether the robot
stayed up. The last line is JSON:
`{"outcome", "reason", "sim_time_s", "wall_time_s", "rtf", "locomotion", "recording"}`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from common.bus import WaitTimeout
from common.config import resolve
from common.keys import WORLD_CLOCK
from common.messages.sim import Clock, Odom
from common.recording import run_dir
from common.stack import Supervised

#: The services `dume up` runs (supervisord's programs that start by default).
SERVICES = ("sim", "wbc", "perception", "semantic_map", "navigation")
#: The base is down when it sinks this low (the B1 stands at about 0.53 m).
FALLEN_BELOW_M = 0.35


def run_demo(args: argparse.Namespace) -> int:
    overrides = [
        f"sim.world_seed={args.world_seed}",
        f'sim.world="{args.world}"',
        "recording.enabled=true",
        *args.set,
    ]
    stack = Supervised(overrides, port=args.port)
    recording = run_dir(stack.config.recording, stack.run_id)
    print(
        f"dume demo: {args.world} world seed {args.world_seed}, port {stack.port}, "
        f"run {stack.run_id}",
        file=sys.stderr,
    )
    wall0 = time.perf_counter()
    stack.start()
    outcome, reason, sim_s, lowest = "failed", "", 0.0, float("inf")
    locomotion = stack.config.sim.locomotion
    try:
        stack.wait_ready(list(SERVICES), timeout_s=120)
        clock = stack.bus.latest(WORLD_CLOCK, Clock)
        odom = stack.bus.latest(stack.keys.odom, Odom)
        deadline_ns = round(args.duration * 1e9)
        last_print = -1
        while True:
            try:
                c = clock.wait(lambda c: c.stamp_ns > last_print, 30.0)  # noqa: B023
            except WaitTimeout:
                reason = "the simulator stopped publishing its clock"
                break
            o = odom.get()
            if o is not None:
                lowest = min(lowest, o.base_position_in_world[2])
                locomotion = o.locomotion
            if c.stamp_ns // 1_000_000_000 != last_print // 1_000_000_000:
                print(
                    f"  t={c.stamp_ns / 1e9:5.1f} s  rtf {c.rtf:4.2f}  "
                    f"base {o.base_position_in_world[2] if o else float('nan'):.3f} m",
                    file=sys.stderr,
                )
            last_print = c.stamp_ns
            sim_s = c.stamp_ns / 1e9
            if c.stamp_ns >= deadline_ns:
                stood = lowest > FALLEN_BELOW_M
                gone = sorted(set(SERVICES) - stack.alive())
                outcome = "succeeded" if stood and not gone else "failed"
                reason = (
                    f"the base sank to {lowest:.3f} m"
                    if not stood
                    else f"services down at the end: {gone}"
                    if gone
                    else f"stood {sim_s:.1f} s with every service up; lowest base {lowest:.3f} m"
                )
                break
    except WaitTimeout as exc:
        reason = f"the stack did not come up: {exc}"
    finally:
        stack.stop()
    wall = time.perf_counter() - wall0
    print(
        json.dumps(
            {
                "outcome": outcome,
                "reason": reason,
                "sim_time_s": round(sim_s, 3),
                "wall_time_s": round(wall, 2),
                "rtf": round(sim_s / wall, 3) if wall > 0 else 0.0,
                "locomotion": locomotion,
                "recording": str(recording.relative_to(resolve("."))),
            }
        )
    )
    return 0 if outcome == "succeeded" else 1
