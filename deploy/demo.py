"""`dume demo`: start a stack under supervisord, ask for an object, follow it, stop, and
print one JSON line.

The stack is every service (`SERVICES`) under supervisord (`deploy.stack.Supervised`),
lockstep, its logs and recording in `var/run/<run>/` (`deploy.runs`). The semantic map,
in a fresh database of its own, starts from the world's saved map (`--map saved`: the
robot's own, explored from nothing, `deploy.maps`) or a map file (`--map FILE`), with no
floor plan, the robot localizing on the map's own grid; or, with `--map truth` (the
default for now: the saved hall map still holds false people, and the demo asks for the
person farthest away), from the world's truth positions with noise (`semantic_map.start
= "seed-from-world"`, with the floor plan: the ablation standing in for a mapping run).
Once every service is ready the demo asks, by map ids, for the bottle and the person
farthest apart in the map (the longest job), or for the `--object` (an id or a class)
and `--person` given, the other side chosen far from it. Progress goes to stderr: each
status change, and every sim second the behaviour, progress, sim time and real-time
factor. The outcome is `succeeded` when the mission says so and the sim's truth agrees
(its `HandoverTaken` event: the object the requested map id stands for in the requested
person's hand); exit code 0 only then. The last line: `{"outcome", "reason",
"sim_time_s", "wall_time_s", "rtf", "locomotion", "recording", "digest"}`: the digest
fingerprints the run (`bench.eval.judge.run_digest`: the status timeline and the base's
trajectory at 10 Hz), so two runs of one seed can be compared;
`var/run/<run>/record.json` holds what it was made of.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import msgspec

from bench.eval.judge import WorldResult, evaluate
from bench.eval.run import (
    DEPENDENCY_LOST,
    read_back,
    read_map,
    read_world,
    request_result,
    sigterm_interrupts,
    start_gate_overrides,
    watch_mission,
)
from bench.eval.targets import TargetError, demo_pair
from common.bus import BusError
from common.config import load_config, merged, parse_overrides
from common.messages import PayloadError
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.sim import Clock
from common.recording import new_run_id, run_dir
from deploy.maps import start_from
from deploy.runs import shown
from deploy.stack import Supervised
from services.semantic_map.store import database_path, remove_database

#: The services `dume up` runs (supervisord's programs that start by default).
SERVICES = ("sim", "wbc", "perception", "semantic_map", "navigation", "localization", "mission")
#: Wall seconds for every service to be ready, and for supervisord to stop them all.
READY_TIMEOUT_S = 300.0
STOP_TIMEOUT_S = 180.0


def demo_overrides(args: argparse.Namespace, map_name: str) -> dict[str, Any]:
    """The demo stack's settings: the world, the recording, a fresh map of its own."""
    site = load_config({"sim.world": args.world, "sim.world_seed": args.world_seed}).map_site()
    start = start_from(args.map, site)
    return merged(
        {
            "sim.world_seed": args.world_seed,
            "sim.world": args.world,
            "recording.enabled": True,
        },
        start,
        {"semantic_map.name": map_name, "semantic_map.reset": True},
        start_gate_overrides(),
        parse_overrides(args.set),
    )


def _show(status: MissionStatus | None, clock: Clock, changed: bool) -> None:
    # A change at the sim time it happened (the same in every run of the seed).
    now = status.stamp_ns if changed and status is not None else clock.stamp_ns
    t = f"t={now / 1e9:6.2f} s  rtf {clock.rtf:4.2f}"
    if status is None:
        print(f"  {t}  waiting for the mission's first status", file=sys.stderr)
        return
    why = "  " + ": ".join(x for x in (status.reason, status.detail) if x)
    mark = "→" if changed else " "
    print(
        f"{mark} {t}  {status.state:9s} {status.behaviour or '-':18s} "
        f"{100 * status.progress:3.0f} %{why}",
        file=sys.stderr,
        flush=True,
    )


def _ask(stack: Supervised, args: argparse.Namespace, result: WorldResult) -> str:
    """Choose, send and follow the request; fill `result`. Returns the locomotion."""
    bus, keys = stack.bus, stack.keys
    world, (arts, people) = read_world(bus), read_map(bus)
    pair = demo_pair(arts, people, args.object, args.person)
    request_result(result, pair, arts, people, world)
    request = MissionRequest(
        request_id=f"demo-{stack.run_id}", object=pair.object, person=pair.person
    )
    far = "" if pair.distance_m != pair.distance_m else f", {pair.distance_m:.1f} m apart"
    print(f"dume demo: asking for {pair.object} for {pair.person}{far}", file=sys.stderr)
    record = watch_mission(bus, keys, request, args.timeout, _show, start_gate=True)
    evaluate(result, record, world)
    # What the digest is made of, to compare two runs sample by sample.
    (stack.run_dir / "record.json").write_bytes(
        msgspec.json.encode(
            {
                "digest": result.digest,
                "changes": record.changes,
                "trajectory": record.trajectory,
                "events": record.events,
            }
        )
    )
    return read_back(bus, keys, timeout_s=30.0)["locomotion"]


def _verdict(result: WorldResult) -> tuple[str, str]:
    """The demo's outcome and reason: the mission's success, confirmed by truth."""
    if result.error:
        return "failed", result.error
    mission = result.mission_state or "no final status"
    said = ": ".join(x for x in (result.mission_reason, result.mission_detail) if x)
    if result.mission_reason == DEPENDENCY_LOST:  # nobody waits for the dead
        return "failed", f"{said} (the mission was in {result.last_behaviour or '-'})"
    if result.mission_state == "succeeded" and result.succeeded:
        return "succeeded", f"{result.truth_reason} (asked: {result.object} for {result.person})"
    if result.mission_state == "succeeded":
        return "failed", f"the mission said succeeded but {result.truth_reason}"
    return "failed", f"mission {mission} in {result.last_behaviour or '-'}: {said or '-'}"


def run_demo(args: argparse.Namespace) -> int:
    run_id = new_run_id()
    map_name = f"demo-{run_id}"
    stack = Supervised(demo_overrides(args, map_name), port=args.port, run_id=run_id)
    recording = run_dir(stack.config.recording, stack.run_id)
    start = (
        "seed-from-world (truth + noise: the ablation)"
        if args.map == "truth"
        else f"the saved map {shown(Path(str(stack.config.semantic_map.prior_file)))}"
    )
    print(
        f"dume demo: {args.world} world seed {args.world_seed}, map {start}, "
        f"port {stack.port}, run {stack.run_id}\n"
        f"dume demo: logs and recording in {shown(stack.run_dir)}/ (dume logs, dume view)",
        file=sys.stderr,
        flush=True,
    )
    wall0 = time.perf_counter()
    result = WorldResult(world=args.world, world_seed=args.world_seed, scenario="demo")
    locomotion: str = stack.config.sim.locomotion
    step = "bring the stack up"
    with sigterm_interrupts():
        try:
            stack.start()
            stack.wait_ready(list(SERVICES), timeout_s=READY_TIMEOUT_S)
            step = "run the request"
            locomotion = _ask(stack, args, result)
            result.services_down = sorted(set(SERVICES) - stack.alive())
        except (BusError, PayloadError, TargetError) as exc:
            result.error = f"could not {step}: {exc}"
        finally:
            # supervisord stops the services one by one and the sim flushes its recording:
            # under load that takes longer than `Supervised.stop`'s default wait.
            stack.stop(timeout_s=STOP_TIMEOUT_S)
            remove_database(database_path(stack.config.semantic_map, map_name))
    outcome, reason = _verdict(result)
    if result.services_down:
        outcome, reason = "failed", f"{reason}; services down at the end: {result.services_down}"
    wall = time.perf_counter() - wall0
    print(
        json.dumps(
            {
                "outcome": outcome,
                "reason": reason,
                "sim_time_s": result.sim_time_s,
                "wall_time_s": round(wall, 2),
                "rtf": result.rtf,
                "locomotion": locomotion,
                "recording": shown(recording),
                "digest": result.digest,
            }
        )
    )
    return 0 if outcome == "succeeded" else 1
