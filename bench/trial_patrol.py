"""`dume trial patrol`: a mapping patrol from an empty map, scored against the sim's truth.

`patrol_run` starts router + sim + wbc + perception + semantic_map + navigation +
mission as processes (lockstep, dynamic locomotion, the network segmenter unless
overridden), the map empty in a fresh database with the world's floor plan, navigation on
the map's occupancy. It asks the mission for a patrol (`dume/<r>/mission/patrol`; the
mission walks it through navigation, the map fuses what perception sees), waits for it to
end, and reads the map's artifacts and people. `score` matches them to the world
description (truth, for evaluation only) one to one by class and nearest position within
`MATCH_M`: artifacts found / total with their horizontal position errors (median, max;
the acceptance is every artifact within 10 cm), people found / in the world, false
entries (map entities matching nothing), the ids given, patrol sim time, wall time and
the real-time factor.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from bench.eval.run import START_GATE, start_gate_overrides
from common.config import Overrides, merged
from common.keys import MAP_ARTIFACTS, MAP_PEOPLE, WORLD_CLOCK, WORLD_DESCRIPTION
from common.messages.mission import PatrolRequest, PatrolStatus
from common.messages.semantic_map import MapEntity, MapListing
from common.messages.sim import Clock
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack

SERVICES = ["sim", "wbc", "perception", "semantic_map", "navigation", "mission"]
#: A map entity further than this from every truth of its class is a false entry, m.
MATCH_M = 0.5
PERSON_MATCH_M = 1.0


def patrol_settings(world: str, seed: int, db_dir: str) -> dict[str, Any]:
    return {
        "sim.world": world,
        "sim.world_seed": seed,
        "sim.locomotion": "dynamic",
        "semantic_map.dir": db_dir,
        "semantic_map.name": "patrol",
        "semantic_map.reset": True,
        "semantic_map.start": "empty",
        "semantic_map.floor_plan": "world",
        "navigation.map_source": "map",
    }


def _match(
    entities: list[MapEntity], truths: Sequence[tuple[str, str, np.ndarray]], gate_m: float
) -> tuple[dict[str, tuple[str, float]], list[str]]:
    """One-to-one by class, nearest first: {truth id: (map id, horizontal error)}, and
    the map ids matching nothing."""
    pairs = []
    for e in entities:
        p = np.array(e.position_in_world[:2])
        for tid, cls, xy in truths:
            if cls == e.class_name:
                d = float(np.linalg.norm(p - xy))
                if d <= gate_m:
                    pairs.append((d, e.id, tid))
    pairs.sort()
    found: dict[str, tuple[str, float]] = {}
    used: set[str] = set()
    for d, eid, tid in pairs:
        if tid in found or eid in used:
            continue
        found[tid] = (eid, d)
        used.add(eid)
    return found, [e.id for e in entities if e.id not in used]


def score(
    world: WorldDescription, artifacts: list[MapEntity], people: list[MapEntity]
) -> dict[str, Any]:
    """The map against the world's truth (see the module docstring)."""
    arts = [(a.id, a.object_class, np.array(a.position[:2])) for a in world.artifacts]
    found_a, false_a = _match(artifacts, arts, MATCH_M)
    persons = [(p.id, "person", np.array(p.position[:2])) for p in world.people]
    found_p, false_p = _match(people, persons, PERSON_MATCH_M)
    errors = [d for _id, d in found_a.values()]
    return {
        "artifacts_found": len(found_a),
        "artifacts_total": len(arts),
        "artifacts_within_10cm": sum(d <= 0.10 for d in errors),
        "artifact_error_median_mm": round(1e3 * float(np.median(errors)), 2) if errors else None,
        "artifact_error_max_mm": round(1e3 * max(errors), 2) if errors else None,
        "artifacts_missed": sorted(t for t, _c, _p in arts if t not in found_a),
        "people_found": len(found_p),
        "people_total": len(persons),
        "people_missed": sorted(t for t, _c, _p in persons if t not in found_p),
        "false_entries": {
            e.id: {"observations": e.observations, "missing": e.missing_since_ns is not None}
            for e in [*artifacts, *people]
            if e.id in {*false_a, *false_p}
        },
        "ids": {tid: eid for tid, (eid, _d) in sorted({**found_a, **found_p}.items())},
        "errors_mm": {tid: round(1e3 * d, 2) for tid, (_e, d) in sorted(found_a.items())},
    }


#: Wall seconds the start query is given to reach the mission's queue before the sim
#: starts (loopback: milliseconds; late, it starts a tick or two later, as before).
HOLD_S = 1.0


def _start_held(s: ProcessStack, request: PatrolRequest) -> PatrolStatus:
    """Ask for the patrol while the sim holds at t = 0 (the mission answers once its
    first tick took it), then let the sim start; the answer."""
    answer: list[PatrolStatus | BaseException] = []

    def ask() -> None:
        try:
            answer.append(s.bus.query(s.keys.mission_patrol, request, PatrolStatus, 60.0))
        except BaseException as exc:  # handed to the caller
            answer.append(exc)

    asking = threading.Thread(target=ask, daemon=True)
    asking.start()
    time.sleep(HOLD_S)
    s.bus.declare_alive(s.keys.alive(START_GATE))  # the sim starts now
    asking.join(90.0)
    if not answer:
        raise TimeoutError("the mission did not answer the patrol's start")
    if isinstance(answer[0], BaseException):
        raise answer[0]
    return answer[0]


def patrol_run(
    world: str = "hall",
    seed: int = 0,
    overrides: Overrides | None = None,
    spacing_m: float = 0.0,
    timeout_s: float = 7200.0,
    db_dir: str | None = None,
) -> dict[str, Any]:
    """Run a patrol on a fresh stack; the figures (JSON-ready)."""
    tmp = None
    if db_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="dume-patrol-")
        db_dir = tmp.name
    # The sim held at t = 0 until the patrol's start waits in the mission, so that the
    # mission takes it at its first tick in every run (asked once the clock ran, it
    # started at 0.15 s in one run and at 0.60 s in another, and the two mapped apart).
    settings = merged(patrol_settings(world, seed, db_dir), start_gate_overrides(),
                      overrides or {})  # fmt: skip
    out: dict[str, Any] = {"trial": "patrol", "world": world, "world_seed": seed}
    s = ProcessStack(SERVICES, settings)
    try:
        s.start(timeout_s=180.0)
        truth = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 30.0)
        clock = s.bus.latest(WORLD_CLOCK, Clock)
        start = _start_held(s, PatrolRequest(action="start", spacing_m=spacing_m))
        t0_wall, t0_sim = time.perf_counter(), 0
        status = start
        deadline = time.monotonic() + timeout_s
        while status.state == "running" and time.monotonic() < deadline:
            time.sleep(2.0)
            status = s.bus.query(
                s.keys.mission_patrol, PatrolRequest(action="status"), PatrolStatus, 30.0
            )
        wall = time.perf_counter() - t0_wall
        sim_s = (clock.get().stamp_ns - t0_sim) / 1e9  # type: ignore[union-attr]
        artifacts = s.bus.query(MAP_ARTIFACTS, None, MapListing, 30.0).entities
        people = s.bus.query(MAP_PEOPLE, None, MapListing, 30.0).entities
    finally:
        s.stop()
        if tmp is not None:
            tmp.cleanup()
    out |= {
        "patrol_state": status.state,
        "patrol_reason": status.reason,
        "patrol_detail": status.detail,
        "viewpoints": status.waypoints,
        "travelled_m": round(status.travelled_m, 2),
        **score(truth, artifacts, people),
        "patrol_sim_s": round(sim_s, 1),
        "wall_s": round(wall, 1),
        "rtf": round(sim_s / wall, 3) if wall > 0 else math.nan,
    }
    return out
