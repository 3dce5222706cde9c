"""One bring-me request on a live stack, watched from outside: what `dume demo` and
`dume eval` share.

`read_map` lists the semantic map (the request's candidates); `read_world` asks the sim
for its truth; `read_back` reads the settings the stack actually runs with from what it
publishes (the segmenter on every `Detections`, the locomotion on every `Odom`), not
from the launcher's config. `watch_mission` subscribes to the mission's status, the
world's events and the clock, sends the request once the mission's subscriber matches,
and follows it to a final state, a sim-time timeout (then it cancels the request), a
clock that stops, or a dependency lost: the sim or the mission going away or restarting
(their liveliness), or the mission saying it has no request in progress after it had
ours, end the watch with `dependency_lost: <who> …` (nobody waits for the dead). A
token that went is first doubted (`OwnLink`): when every watched token is back and the
clock ran on within `LAPSE_GRACE_S` of wall time, it was this watcher's own link that
lapsed (the router cut off a client that stalled 0.5 s or outlived its 1 s lease: a
loaded CI machine, a SIGSTOP), not the robot's: the watch goes on, the lapse kept in the
record; a final status that comes meanwhile ends it as usual.
`on_progress` sees every status change and every sim second. It never sleeps on wall
time except in waits with timeouts. `sigterm_interrupts` turns
SIGTERM into KeyboardInterrupt so that a killed demo or eval still stops its stack.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

from bench.estimate_errors import Estimates, PlacementErrors
from bench.eval.judge import (
    TERMINAL,
    TRAJECTORY_EVERY_NS,
    MissionRecord,
    WorldResult,
    transitions,
)
from bench.eval.judge import truth_object as match_object
from bench.eval.judge import truth_person as match_person
from bench.eval.targets import Pair
from common.bus import Bus, Fifo, Latest, WaitTimeout
from common.keys import (
    MAP_ARTIFACTS,
    MAP_PEOPLE,
    WORLD_CLOCK,
    WORLD_DESCRIPTION,
    WORLD_EVENTS,
    RobotKeys,
)
from common.lifelines import Dependencies, OwnLink
from common.messages.localization import Localization
from common.messages.mission import MissionCancel, MissionReceipt, MissionRequest, MissionStatus
from common.messages.perception import Detections
from common.messages.semantic_map import MapEntity, MapListing
from common.messages.sim import Clock, Odom, StateTruth, WorldEvents
from common.messages.world import WorldDescription

#: Called with the request's status (None before the first), the clock, and whether the
#: status just changed (otherwise: another sim second went by).
Progress = Callable[[MissionStatus | None, Clock, bool], None]
#: Wall seconds without a clock tick after which the sim is taken as stopped.
STALL_WALL_S = 120.0
#: Sim seconds of world events still collected after the final status.
GRACE_S = 1.0
#: The typed reason of a watch that ended because a service it depends on went away.
DEPENDENCY_LOST = "dependency_lost"
#: The lockstep participant (role `start`) a gated watch comes alive as (`watch_mission`).
START_GATE = "client"
#: The services a watch of one request depends on: the clock's and the request's.
WATCHED = ("sim", "mission")


@contextlib.contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt while inside, so a killed demo or eval still
    tears its stack down in its `finally`."""

    def handler(_sig: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def read_map(bus: Bus, timeout_s: float = 10.0) -> tuple[list[MapEntity], list[MapEntity]]:
    """The map's artifacts and people (missing ones included; the choosers skip them)."""
    arts = bus.query(MAP_ARTIFACTS, None, MapListing, timeout_s).entities
    people = bus.query(MAP_PEOPLE, None, MapListing, timeout_s).entities
    return arts, people


def read_world(bus: Bus, timeout_s: float = 10.0) -> WorldDescription:
    """The sim's world description (truth: for judging only)."""
    return bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s)


def read_back(bus: Bus, keys: RobotKeys, timeout_s: float = 60.0) -> dict[str, str]:
    """`{"segmenter", "locomotion"}` as the running perception and sim report them."""
    dets = bus.latest(keys.detections, Detections)
    odom = bus.latest(keys.odom, Odom)
    out = {"segmenter": "unknown", "locomotion": "unknown"}
    try:
        with contextlib.suppress(WaitTimeout):
            out["locomotion"] = odom.wait(lambda _o: True, timeout_s).locomotion
        with contextlib.suppress(WaitTimeout):
            out["segmenter"] = dets.wait(lambda _d: True, timeout_s).segmenter
    finally:
        dets.undeclare()
        odom.undeclare()
    return out


def request_result(
    base: WorldResult,
    pair: Pair,
    artifacts: list[MapEntity],
    people: list[MapEntity],
    world: WorldDescription,
) -> WorldResult:
    """`base` with the request's targets and the truth ids they stand for, now."""
    base.object, base.person, base.distance_m = pair.object, pair.person, pair.distance_m
    obj = next((a for a in artifacts if a.id == pair.object), None)
    who = next((p for p in people if p.id == pair.person), None)
    o = match_object(world, obj.position_in_world[:2]) if obj else None
    p = match_person(world, who.position_in_world[:2]) if who else None
    base.truth_object = o.id if o else ""
    base.truth_person = p.id if p else ""
    base.truth_match_m = (
        round(o.distance_m, 3) if o else float("nan"),
        round(p.distance_m, 3) if p else float("nan"),
    )
    return base


def start_gate_overrides() -> dict[str, Any]:
    """The stack settings that let `watch_mission(start_gate=True)` start the run: the sim
    waits at t = 0 for the `START_GATE` client too."""
    return {f"time.participants.{START_GATE}.role": "start"}


def watch_mission(
    bus: Bus,
    keys: RobotKeys,
    request: MissionRequest,
    timeout_s: float,
    on_progress: Progress | None = None,
    start_gate: bool = False,
) -> MissionRecord:
    """Send `request`, follow it until a final state or `timeout_s` of sim time.

    With `start_gate` (a stack with `start_gate_overrides`, its sim held at t = 0 for
    us) the request goes as a `mission/submit` query, and only once the mission holds it
    does this client come alive and let the sim start: the mission takes it at its first
    tick, in every run. Without, it is put once the clock runs, at whatever tick.
    """
    statuses = bus.fifo(keys.mission_status, MissionStatus, maxlen=1 << 16)
    events = bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=1 << 16)
    clock = bus.latest(WORLD_CLOCK, Clock)
    poses = _Poses(bus, keys)
    publisher = bus.publisher(keys.mission_request, MissionRequest, "control")
    alive = bus.watch_alive(keys.alive_all)
    deps = Dependencies(alive.lifelines, WATCHED, keys.alive)
    wall0 = time.perf_counter()
    record = MissionRecord(request=request, start_ns=0)
    try:
        if not start_gate:
            clock.wait(lambda _c: True, STALL_WALL_S)
            _wait_matching(publisher.has_subscribers, 10.0)
        with contextlib.suppress(WaitTimeout):
            alive.wait_for({keys.alive(n) for n in WATCHED}, 10.0)
        if down := deps.missing():
            record.ended = f"{DEPENDENCY_LOST}: not running: {', '.join(down)}"
            return record
        deps.arm()
        if start_gate:
            bus.query(keys.mission_submit, request, MissionReceipt, 30.0)
            bus.declare_alive(keys.alive(START_GATE))  # the sim starts now
        else:
            now = clock.get()
            record.start_ns = record.end_ns = now.stamp_ns if now else 0
            publisher.put(request)
        wall0 = time.perf_counter()
        poses.estimates.start_ns = record.start_ns
        _follow(record, statuses, events, clock, poses, timeout_s, on_progress, deps)
        record.wall_s = time.perf_counter() - wall0
        lost = record.ended.startswith(DEPENDENCY_LOST)
        if not lost and (not record.changes or record.changes[-1].state not in TERMINAL):
            _cancel(bus, keys, record, statuses)
    except WaitTimeout:
        record.ended = "the simulator's clock stopped"
    finally:
        record.wall_s = record.wall_s or time.perf_counter() - wall0
        estimates = poses.estimates.figures()
        record.odometry, record.localization = estimates["odometry"], estimates["localization"]
        record.placement = poses.placement.figures()
        poses.undeclare()
        for sub in (statuses, events, clock):
            sub.undeclare()
        alive.undeclare()
        publisher.undeclare()
    return record


def _wait_matching(matched: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not matched() and time.monotonic() < deadline:
        time.sleep(0.05)


def _follow(
    record: MissionRecord,
    statuses: Fifo[MissionStatus],
    events: Fifo[WorldEvents],
    clock: Latest[Clock],
    poses: _Poses,
    timeout_s: float,
    on_progress: Progress | None,
    deps: Dependencies,
) -> None:
    deadline_ns = record.start_ns + round(timeout_s * 1e9)
    rid = record.request.request_id
    last_second, final_ns, last_tick = -1, -1, time.monotonic()
    seen: list[MissionStatus] = []
    link = OwnLink()
    while True:
        statuses.wait(0.1)
        forgotten = False
        for s in statuses.drain():
            if s.request_id == rid:
                seen.append(s)
            elif seen and s.state == "idle" and final_ns < 0:
                forgotten = True  # the mission had our request and now has none
        for batch in events.drain():
            record.events.extend(batch.events)
        poses.sample(record)
        changes = transitions(seen, rid)
        gone = deps.lost()
        c = clock.get()
        doubt = link.verdict(gone is not None, time.monotonic(), c.stamp_ns if c else 0,
                             not deps.missing())  # fmt: skip
        if doubt == "lapse":
            deps.arm()
            record.lapses.append(link.lapses[-1] / 1e9)
            print(f"  watch: this client's own link lapsed at t={record.lapses[-1]:.1f} s "
                  f"({gone}); the stack went on", file=sys.stderr, flush=True)  # fmt: skip
        elif doubt == "doubt" and changes and changes[-1].state in TERMINAL and final_ns < 0:
            record.changes = changes  # the mission's own verdict on its loss
            record.end_ns = max(record.end_ns, changes[-1].stamp_ns)
            return
        lost = (gone if doubt == "lost" else None) or (
            "mission restarted: it has no request in progress" if forgotten else None
        )
        if lost is not None and final_ns < 0:
            # What the mission said before it went may still be in: keep all of it.
            seen.extend(s for s in statuses.drain() if s.request_id == rid)
            record.changes = transitions(seen, rid)
            record.ended = f"{DEPENDENCY_LOST}: {lost}"
            record.end_ns = max(record.end_ns, c.stamp_ns if c else 0)
            return
        if c is None:
            continue
        if c.stamp_ns > record.end_ns:
            record.end_ns, last_tick = c.stamp_ns, time.monotonic()
        elif time.monotonic() - last_tick > STALL_WALL_S:
            record.changes = changes
            raise WaitTimeout(f"no clock tick for {STALL_WALL_S:.0f} s")
        if on_progress is not None:
            new = changes[len(record.changes) :]
            for ch in new:
                on_progress(ch, c, True)
            if not new and c.stamp_ns // 1_000_000_000 != last_second:
                on_progress(changes[-1] if changes else None, c, False)
        last_second = c.stamp_ns // 1_000_000_000
        record.changes = changes
        if changes and changes[-1].state in TERMINAL and final_ns < 0:
            final_ns = c.stamp_ns
        if final_ns >= 0 and c.stamp_ns >= final_ns + round(GRACE_S * 1e9):
            record.end_ns = changes[-1].stamp_ns
            return
        if final_ns < 0 and c.stamp_ns >= deadline_ns:
            record.ended = f"no final status within {timeout_s:.0f} s of sim time"
            return


class _Poses:
    """The base's truth, the robot's odometry, its localization and perception's
    detections as they come: the truth's trajectory, and each estimate paired with the
    truth by stamp for its errors (no localization samples in the truth ablation, which
    runs none); the detections' placement until the pick begins (the picked object moves
    from its true place then)."""

    def __init__(self, bus: Bus, keys: RobotKeys) -> None:
        self.detections = bus.fifo(keys.detections, Detections, maxlen=1 << 14)
        self.placement = PlacementErrors(read_world(bus).artifacts)
        self.truth = bus.fifo(keys.state_truth, StateTruth, maxlen=1 << 20)
        self.odom = bus.fifo(keys.odom, Odom, maxlen=1 << 20)
        self.localization = bus.fifo(keys.localization, Localization, maxlen=1 << 16)
        self.estimates = Estimates()

    def undeclare(self) -> None:
        for sub in (self.truth, self.odom, self.localization, self.detections):
            sub.undeclare()

    def sample(self, record: MissionRecord) -> None:
        """Keep the true pose every `TRAJECTORY_EVERY_NS` from the request on."""
        for o in self.odom.drain():
            self.estimates.odom(o)
        for loc in self.localization.drain():
            self.estimates.located(loc)
        if self.placement.stop_ns is None:
            picks = (c.stamp_ns for c in record.changes if c.behaviour == "pick_object")
            self.placement.stop_ns = next(picks, None)
        for det in self.detections.drain():
            self.placement.detections(det)
        for t in self.truth.drain():
            self.estimates.truth(t)
            self.placement.truth(t)
            if t.stamp_ns >= record.start_ns and t.stamp_ns % TRAJECTORY_EVERY_NS == 0:
                record.trajectory.append(
                    (t.stamp_ns, *t.base_position_in_world, *t.base_orientation_xyzw)
                )


def _cancel(
    bus: Bus, keys: RobotKeys, record: MissionRecord, statuses: Fifo[MissionStatus]
) -> None:
    """Cancel a request that outlived its timeout; keep the status that answers it."""
    rid = record.request.request_id
    cancel = bus.publisher(keys.mission_cancel, MissionCancel, "control")
    cancel.put(MissionCancel(request_id=rid, reason="evaluation timeout"))
    cancel.undeclare()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        s = statuses.pop(timeout_s=0.2)
        if s is not None and s.request_id == rid:
            record.changes = transitions([*record.changes, s], rid)
            if s.state in TERMINAL:
                return
