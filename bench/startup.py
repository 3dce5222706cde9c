"""`dume bench startup`: start the demo's stack again and again and count native crashes.

Each round starts every service under supervisord as `dume demo --world small` does
(seed-from-world map, recording on, faulthandler on in every process), waits until all
are ready, asks for the demo's bottle and person, follows the request for `SIM_S` seconds
of sim time (the first inputs of every service, where the mission and navigation used
to die), then stops the stack and reads what supervisord and the services logged: a
process that ended on a signal (`terminated by SIGSEGV`) or a faulthandler report
(`Fatal Python error`) is a crash, named with the log that shows its stack.

    dume bench startup --rounds 50

Figures only, no assertion: the figure to read
is `crashes`. Not part of `dume bench all` (a round is a whole stack's start and stop).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path
from typing import Any

from bench.eval.run import read_map, watch_mission
from bench.eval.targets import demo_pair
from common.bus import BusError
from common.config import Overrides, merged
from common.messages.mission import MissionRequest
from deploy.demo import SERVICES, demo_overrides
from deploy.stack import Supervised

#: Sim seconds each round follows its request before stopping the stack.
SIM_S = 6.0
_SIGNAL = re.compile(r"exited: (\w+) \(terminated by (SIG\w+)")
_FATAL = "Fatal Python error"


def crashes_in(run_dir: Path) -> list[dict[str, str]]:
    """Native crashes a stack's logs show: the process, the signal, the log with its stack."""
    found: list[dict[str, str]] = []
    sup = run_dir / "supervisord.log"
    if sup.exists():
        for m in _SIGNAL.finditer(sup.read_text(errors="replace")):
            found.append({"process": m.group(1), "signal": m.group(2), "log": str(sup)})
    for log in sorted(run_dir.glob("*.log")):
        text = log.read_text(errors="replace")
        if _FATAL in text:
            line = next(x for x in text.splitlines() if _FATAL in x)
            found.append({"process": log.stem.split("-")[0], "signal": line, "log": str(log)})
    return found


def one_round(index: int, overrides: Overrides) -> dict[str, Any]:
    args = argparse.Namespace(world="small", world_seed=0, map=None, set=[])
    stack = Supervised(merged(demo_overrides(args, f"bench-startup-{index}"), overrides))
    wall0 = time.perf_counter()
    error = ""
    try:
        stack.start()
        stack.wait_ready(list(SERVICES), timeout_s=300.0)
        arts, people = read_map(stack.bus)
        pair = demo_pair(arts, people, None, None)
        request = MissionRequest(
            request_id=f"startup-{index}", object=pair.object, person=pair.person
        )
        record = watch_mission(stack.bus, stack.keys, request, SIM_S, start_gate=True)
        states = [c.state for c in record.changes]
        error = record.ended if "running" not in states else ""
    except BusError as exc:
        error = f"{type(exc).__name__}: {exc}"
    finally:
        stack.stop(timeout_s=180.0)
    crashes = crashes_in(stack.run_dir)
    return {
        "round": index,
        "wall_s": round(time.perf_counter() - wall0, 1),
        "crashes": crashes,
        "error": error,
        "run_dir": str(stack.run_dir),
    }


def bench_startup(overrides: Overrides, rounds: int = 10) -> dict[str, Any]:
    results = []
    for i in range(rounds):
        r = one_round(i, overrides)
        results.append(r)
        print(
            f"round {i + 1}/{rounds}: {r['wall_s']:.0f} s, "
            f"{len(r['crashes'])} crash(es) {r['crashes'] or ''} {r['error']}",
            file=sys.stderr,
            flush=True,
        )
    return {
        "rounds": rounds,
        "crashes": sum(len(r["crashes"]) for r in results),
        "rounds_with_crash": [r["round"] for r in results if r["crashes"]],
        "rounds_not_running": [r["round"] for r in results if r["error"]],
        "crashed": [c for r in results for c in r["crashes"]],
        "median_round_s": sorted(r["wall_s"] for r in results)[len(results) // 2],
    }
