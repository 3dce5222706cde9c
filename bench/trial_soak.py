"""`dume trial soak [--minutes M]`: requests, one after another, on one stack for M
minutes of wall time (120), and each service's memory and open files over the run.

The stack `dume demo` brings up for the small world (supervisord, every service,
lockstep, its saved map). Request after request goes on `mission/request` as any
client's does, each of the map's artifacts to each of its people in turn, by id and,
every other time, by class ("a bottle"), with `REQUEST_SIM_S` of sim time before the
trial cancels it. Between two requests the hall is put back as it was (the robot is not
reset): somebody takes each artifact from whoever holds it and sets it where the world
had it (`dume/world/artifact_command`, a truth hook: the trial's, never the robot's), and
the map the stack started from is imported again (`dume/map/import`) with its artifacts
under new ids (`renumbered`: the mission remembers what it handed over by map id, and
never fetches that entry again). Without that, the first handover would leave nothing
to fetch and the soak would measure an idle robot. So every request walks, looks, picks
and hands over, from wherever the last one ended.
Every `SAMPLE_S` of wall time, per service (its supervisord pid): the resident memory
(VmRSS), open file descriptors and threads.

Growth is the median of the last tenth of the samples against the median of the second
tenth (the first is the warm-up: caches, the segmenter's arena, the map filling), in
per cent; a service restarted during the run (a new pid) is reported, its samples
restart. JSON-ready figures, one line per request on stderr.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from bench.eval.run import read_world, start_gate_overrides, watch_mission
from common.config import Overrides, merged
from common.keys import MAP_EXPORT, MAP_IMPORT, WORLD_ARTIFACT_COMMAND, WORLD_CLOCK
from common.messages.mission import MissionRequest
from common.messages.semantic_map import MapFile, MapSummary
from common.messages.sim import ArtifactCommand, Clock
from common.recording import new_run_id
from deploy.demo import SERVICES, demo_overrides
from deploy.stack import Supervised
from services.semantic_map.store import database_path, remove_database

Figures = dict[str, Any]
#: Sim seconds a request has before the trial cancels it: a small-world fetch takes
#: 66-69 s, one whose first handover is not taken goes round the person (about 30 s
#: more); with 90 s those were cancelled holding the object, and the put-back that
#: followed took it out of the gripper (the next request failed `busy` or
#: `object_dropped`).
REQUEST_SIM_S = 180.0
#: Wall seconds between two samples of the services' figures.
SAMPLE_S = 30.0
#: Sim seconds after a request's end at which the hall is put back.
RESET_AFTER_S = 0.5


def process_figures(pid: int) -> dict[str, int]:
    """VmRSS (kB), open file descriptors and threads of a process."""
    out = {"rss_kb": -1, "fds": -1, "threads": -1}
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                out["rss_kb"] = int(line.split()[1])
            elif line.startswith("Threads:"):
                out["threads"] = int(line.split()[1])
        out["fds"] = len(list(Path(f"/proc/{pid}/fd").iterdir()))
    except (OSError, ValueError):
        pass
    return out


def growth(samples: list[dict[str, Any]], field: str) -> float | None:
    """Per cent from the second tenth's median to the last tenth's (see the docstring)."""
    values = [s[field] for s in samples if s[field] >= 0]
    if len(values) < 10:
        return None
    tenth = len(values) // 10
    base = float(np.median(values[tenth : 2 * tenth]))
    end = float(np.median(values[-tenth:]))
    return round(100.0 * (end - base) / base, 2) if base > 0 else None


def renumbered(mf: MapFile) -> MapFile:
    """`mf` with every artifact under the next free id of its class (`bottle_1` →
    `bottle_2` for a file whose counter says 1), the counters moved on."""
    counters = dict(mf.counters)
    entities = []
    for e in mf.entities:
        if e.kind == "artifact":
            counters[e.class_name] = counters.get(e.class_name, 0) + 1
            e = msgspec.structs.replace(e, id=f"{e.class_name}_{counters[e.class_name]}")
        entities.append(e)
    return msgspec.structs.replace(mf, entities=entities, counters=counters)


def run_soak(minutes: float, overrides: Overrides) -> Figures:
    """The soak (see the module docstring)."""
    run_id = new_run_id()
    map_name = f"soak-{run_id}"
    args = argparse.Namespace(world="small", world_seed=0, map="saved", set=[])
    settings = merged(demo_overrides(args, map_name), {"recording.enabled": False}, overrides)
    # requests are put on mission/request: no start gate to hold the sim at t = 0
    settings = {k: v for k, v in settings.items() if k not in start_gate_overrides()}
    stack = Supervised(settings, run_id=run_id)
    db = database_path(stack.config.semantic_map, map_name)
    samples: dict[str, list[dict[str, Any]]] = {s: [] for s in SERVICES}
    pids: dict[str, int] = {}
    restarted: Counter[str] = Counter()
    outcomes: Counter[str] = Counter()
    wall0 = time.perf_counter()
    stopped = ""
    try:
        stack.start()
        stack.wait_ready(list(SERVICES), timeout_s=300.0)
        bus, keys = stack.bus, stack.keys
        the_map = [bus.query(MAP_EXPORT, None, MapFile, 10.0)]
        people = [e for e in the_map[0].entities if e.kind == "person"]
        homes = [(a.id, a.position, a.yaw) for a in read_world(bus).artifacts]
        mover = bus.publisher(WORLD_ARTIFACT_COMMAND, ArtifactCommand, "control")
        clock = bus.latest(WORLD_CLOCK, Clock)
        last = [0.0]

        def _put_back() -> None:
            """Every artifact where the world had it, and the map as the stack started
            (its artifacts renumbered)."""
            at_ns = clock.wait(lambda _c: True, 30.0).stamp_ns + round(RESET_AFTER_S * 1e9)
            for art, position, yaw in homes:
                mover.put(ArtifactCommand(stamp_ns=at_ns, artifact_id=art, position=position,
                                          yaw=yaw))  # fmt: skip
            clock.wait(lambda c: c.stamp_ns > at_ns, 30.0)
            the_map[0] = renumbered(the_map[0])
            bus.query(MAP_IMPORT, the_map[0], MapSummary, 10.0)

        def _one_request(k: int) -> int:
            listed = [e for e in the_map[0].entities if e.kind == "artifact"]
            art = listed[(k // 2) % len(listed)]
            person = people[(k // 2 // len(listed)) % len(people)].id
            name = art.id if k % 2 == 0 else art.class_name
            request = MissionRequest(request_id=f"soak-{k}", object=name, person=person)
            record = watch_mission(bus, keys, request, REQUEST_SIM_S, sample)
            final = record.changes[-1] if record.changes else None
            said = f"{final.state} {final.reason}" if final else record.ended or "no status"
            outcomes[said.strip()] += 1
            t_min = (time.perf_counter() - wall0) / 60.0
            now = {n: (s[-1]["rss_kb"] // 1024, s[-1]["fds"], s[-1]["threads"])
                   for n, s in samples.items() if s}  # fmt: skip
            print(f"{t_min:6.1f} min request {k} {name} → {person}: {said} at "
                  f"{(record.end_ns - record.start_ns) / 1e9:.1f} s; "
                  f"RSS MB, fds, threads {now}", file=sys.stderr, flush=True)  # fmt: skip
            _put_back()
            return k + 1

        def sample(*_: object) -> None:
            """Every `SAMPLE_S` of wall time (called each sim second by the watch)."""
            now = time.perf_counter()
            if now - last[0] < SAMPLE_S:
                return
            last[0] = now
            for name in SERVICES:
                pid = int(stack.ctl("pid", name).strip() or 0)
                if name in pids and pid != pids[name]:
                    restarted[name] += 1
                    samples[name] = []
                pids[name] = pid
                figures = process_figures(pid)
                samples[name].append({"t_min": round((now - wall0) / 60.0, 2), **figures})

        k = 0
        while time.perf_counter() - wall0 < minutes * 60.0 and not stopped:
            try:
                k = _one_request(k)
            except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the figures so far still count
                stopped = "interrupted"
    finally:
        stack.stop(timeout_s=180.0)
        remove_database(db)
    return {
        "trial": "soak",
        "stopped": stopped,
        "minutes": round((time.perf_counter() - wall0) / 60.0, 1),
        "requests": sum(outcomes.values()),
        "outcomes": dict(outcomes),
        "restarted": dict(restarted),
        "services": {
            n: {
                "samples": len(s),
                "rss_mb_first_last_max": [round(s[0]["rss_kb"] / 1024, 1),
                                          round(s[-1]["rss_kb"] / 1024, 1),
                                          round(max(x["rss_kb"] for x in s) / 1024, 1)]
                if s else None,
                "rss_growth_pct": growth(s, "rss_kb"),
                "fds_first_last": [s[0]["fds"], s[-1]["fds"]] if s else None,
                "threads_first_last": [s[0]["threads"], s[-1]["threads"]] if s else None,
            }
            for n, s in samples.items()
        },
    }  # fmt: skip
