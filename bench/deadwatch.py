"""`dume bench deadwatch`: kill the mission early in a run; how soon the watcher says so.

Each round starts the small world's stack twice over, as `dume demo` runs it (under
supervisord, which restarts the mission) and as `dume eval` runs it (plain processes),
hands the bring-me request over as they do, and SIGKILLs the mission once the clock
passes `KILL_AT_S` of sim time. The figures: the wall and sim seconds from the kill to
the end of the watch, and the reason the run was judged failed with (the eval's
`WorldResult.mission_reason` / `mission_detail`): `dependency_lost: mission is gone` or
`… restarted`, never a timeout.

    dume bench deadwatch --rounds 3
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import sys
import threading
import time
from typing import Any

from bench.eval.judge import MissionRecord, WorldResult, evaluate
from bench.eval.run import read_map, read_world, watch_mission
from bench.eval.targets import demo_pair
from common.bus import WaitTimeout
from common.keys import WORLD_CLOCK
from common.messages.mission import MissionRequest
from common.messages.sim import Clock
from deploy.demo import SERVICES, demo_overrides
from deploy.stack import ProcessStack, Supervised

#: Sim seconds into the run at which the mission is killed.
KILL_AT_S = 0.5


def _kill_mission(stack: Supervised | ProcessStack) -> None:
    if isinstance(stack, ProcessStack):
        stack.kill("mission")
        return
    pid = int(stack.ctl("pid", "mission").strip())
    os.kill(pid, signal.SIGKILL)


def one_round(kind: str, index: int) -> dict[str, Any]:
    args = argparse.Namespace(world="small", world_seed=0, map=None, set=[])
    overrides = demo_overrides(args, f"bench-deadwatch-{kind}-{index}")
    stack: Supervised | ProcessStack = (
        Supervised(overrides) if kind == "demo" else ProcessStack(list(SERVICES), overrides)
    )
    try:
        stack.start()
        stack.wait_ready(list(SERVICES), timeout_s=300.0)
        bus, keys = stack.bus, stack.keys
        world, (arts, people) = read_world(bus), read_map(bus)
        pair = demo_pair(arts, people, None, None)
        request = MissionRequest(
            request_id=f"deadwatch-{index}", object=pair.object, person=pair.person
        )
        records: list[MissionRecord] = []
        watch = threading.Thread(
            target=lambda: records.append(watch_mission(bus, keys, request, 600.0, start_gate=True))
        )
        clock = bus.latest(WORLD_CLOCK, Clock)
        watch.start()
        killed_at = clock.wait(lambda c: c.stamp_ns >= KILL_AT_S * 1e9, 300.0)
        _kill_mission(stack)
        wall0 = time.perf_counter()
        watch.join(timeout=600.0)
        wall = time.perf_counter() - wall0
        (record,) = records
        result = evaluate(WorldResult(world="small", world_seed=0, scenario=kind), record, world)
        return {
            "kind": kind,
            "wall_s": round(wall, 2),
            "sim_s": round((record.end_ns - killed_at.stamp_ns) / 1e9, 3),
            "reason": f"{result.mission_reason}: {result.mission_detail}",
            "outcome": result.outcome,
        }
    except WaitTimeout as exc:
        return {"kind": kind, "wall_s": float("nan"), "sim_s": float("nan"), "reason": str(exc)}
    finally:
        stack.stop()


def bench_deadwatch(rounds: int) -> dict[str, Any]:
    out: dict[str, Any] = {"rounds": rounds, "kill_at_s": KILL_AT_S}
    for kind in ("demo", "eval"):
        results = []
        for i in range(rounds):
            r = one_round(kind, i)
            results.append(r)
            print(f"{kind} round {i + 1}/{rounds}: {r}", file=sys.stderr, flush=True)
        walls = [r["wall_s"] for r in results]
        out[kind] = {
            "wall_s_median": statistics.median(walls),
            "wall_s_max": max(walls),
            "sim_s_max": max(r["sim_s"] for r in results),
            "reasons": sorted({r["reason"] for r in results}),
        }
    return out
