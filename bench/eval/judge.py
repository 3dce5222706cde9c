"""Judging one bring-me run against the simulator's truth, and the record of that run.

The request names map ids; the truth it stands for is the world description's artifact
(person) nearest on the floor to the map entity's position at request time — the map's
`seed-from-world` start reuses truth ids with noisy positions, a mapping patrol assigns
its own ids, and this mapping serves both. (People are matched by their position at
t = 0, the world description's; with walking people a request made early in the run
still finds the right one.) The run succeeded when the sim's `HandoverTaken` event names
that object and that person: the object ended in the requested person's hand, whatever
the mission says. The mission's own outcome is recorded beside it, with whether the two
agree.

Stages come from the mission's status changes: a behaviour holds from the stamp of the
status that entered it to the stamp of the next change, so time per stage is sim time.
A stage is passed when a later one was entered, or, for the last, when the mission
succeeded. Pure: no transport.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import msgspec

from common.messages.mission import STAGES, MissionRequest, MissionStatus
from common.messages.sim import HandoverTaken, ObjectDropped, RobotContact, WorldEvent
from common.messages.world import WorldDescription

TERMINAL = frozenset({"succeeded", "failed", "cancelled", "rejected"})


class TruthMatch(NamedTuple):
    """The truth entity a map position stands for, and how far it was from it, m."""

    id: str
    distance_m: float


def nearest_truth(
    xy: tuple[float, float], candidates: Iterable[tuple[str, tuple[float, float]]]
) -> TruthMatch | None:
    """The candidate `(id, (x, y))` nearest to `xy` on the floor; None when there is none."""
    best: TruthMatch | None = None
    for cid, (cx, cy) in candidates:
        d = math.hypot(cx - xy[0], cy - xy[1])
        if best is None or d < best.distance_m:
            best = TruthMatch(cid, d)
    return best


def truth_object(world: WorldDescription, xy: tuple[float, float]) -> TruthMatch | None:
    """The world's artifact nearest to a mapped artifact's floor position."""
    return nearest_truth(xy, ((a.id, (a.position[0], a.position[1])) for a in world.artifacts))


def truth_person(world: WorldDescription, xy: tuple[float, float]) -> TruthMatch | None:
    """The world's person (at t = 0) nearest to a mapped person's floor position."""
    return nearest_truth(xy, ((p.id, p.position) for p in world.people))


class Verdict(NamedTuple):
    """success: the object reached the person's hand. reason: a sentence either way."""

    success: bool
    reason: str


def judge(object_id: str, person_id: str, events: Sequence[WorldEvent]) -> Verdict:
    """Did the sim see `person_id` take `object_id`? Reasons name what happened instead."""
    handovers = [e for e in events if isinstance(e, HandoverTaken)]
    for h in handovers:
        if h.object_id == object_id and h.person_id == person_id:
            return Verdict(True, f"{person_id} took {object_id} at {h.stamp_ns / 1e9:.1f} s")
    wrong = [f"{h.person_id} took {h.object_id}" for h in handovers]
    drops = [  # where: 10 cm below where it was let go, falling (`ObjectDropped`)
        f"{e.object_id} dropped at {e.stamp_ns / 1e9:.1f} s by ({e.position_in_world[0]:.2f}, "
        f"{e.position_in_world[1]:.2f})"
        for e in events
        if isinstance(e, ObjectDropped)
    ]
    what = "; ".join([*wrong, *drops]) or "no handover happened"
    return Verdict(False, f"{object_id} never reached {person_id}'s hand ({what})")


def events_of(events: Iterable[WorldEvent], kind: str) -> list[WorldEvent]:
    """The events of one kind: `handover`, `drop` or `contact`."""
    types = {"handover": HandoverTaken, "drop": ObjectDropped, "contact": RobotContact}[kind]
    return [e for e in events if isinstance(e, types)]


def static_contacts(events: Iterable[WorldEvent], world: WorldDescription) -> list[RobotContact]:
    """The robot's contacts with the world's obstacles (walls, tables, racks…, and a
    movable left in an aisle: a trolley), not with the floor, artifacts or people."""
    obstacles = {o.id for o in world.obstacles} | {m.id for m in world.movables}
    return [e for e in events if isinstance(e, RobotContact) and e.other in obstacles]


def transitions(statuses: Iterable[MissionStatus], request_id: str) -> list[MissionStatus]:
    """The statuses of one request where its state or behaviour changed, in order."""
    out: list[MissionStatus] = []
    for s in statuses:
        if s.request_id != request_id:
            continue
        if not out or (s.state, s.behaviour) != (out[-1].state, out[-1].behaviour):
            out.append(s)
    return out


def stage_times(changes: Sequence[MissionStatus], end_ns: int | None = None) -> dict[str, float]:
    """Sim seconds spent in each behaviour (summed over re-entries), from the changes; a
    run that never reached a final state is in its last behaviour until `end_ns`."""
    out: dict[str, float] = {}
    ends = [c.stamp_ns for c in changes[1:]] + [end_ns if end_ns is not None else -1]
    for s, until in zip(changes, ends, strict=True):
        if s.state in TERMINAL or not s.behaviour or until < 0:
            continue
        out[s.behaviour] = out.get(s.behaviour, 0.0) + max(0, until - s.stamp_ns) / 1e9
    return out


def stages_passed(changes: Sequence[MissionStatus]) -> list[str]:
    """The stages of `STAGES` this run got through, in order."""
    entered = [STAGES.index(s.behaviour) for s in changes if s.behaviour in STAGES]
    furthest = max(entered, default=-1)
    succeeded = bool(changes) and changes[-1].state == "succeeded"
    upto = len(STAGES) if succeeded else furthest
    return list(STAGES[:upto])


def stage_reached(changes: Sequence[MissionStatus]) -> str:
    """The furthest stage of `STAGES` entered ("" when none was)."""
    entered = [STAGES.index(s.behaviour) for s in changes if s.behaviour in STAGES]
    return STAGES[max(entered)] if entered else ""


class WorldResult(msgspec.Struct, kw_only=True):
    """One world's run, as `results.json` lists it.

    outcome: `succeeded` or `failed`, judged from truth; truth_reason says why.
    mission_state, mission_reason, mission_detail: the mission's own last status;
    agree: the mission's success and the truth's are the same.
    error: what kept the run from happening (the stack did not start, …), "" otherwise.
    stage_times_s: sim seconds per behaviour. sim_time_s, wall_time_s: from the request to
    its final status (or the timeout); rtf: their ratio. setup_wall_s: starting the stack.
    contacts_static: robot contacts with static obstacles (`contacts`: who touched what).
    drops: objects that fell (`ObjectDropped`). services_down: stack processes that had
    exited by the end of the run. recording: the run's recording folder ("" when off).
    logs: the run's folder (its services' logs, `deploy.runs`); troubles: a failed run's
    warnings, errors and tracebacks from them (`ProcessStack.troubles`). picture: the world from
    above with the run on it, relative to the report (`pictures.world_picture`);
    failure_frames: the cameras around a failure, drawn from the recording (`--record`).
    digest: the run's fingerprint (`run_digest`): the same seed gives the same digest.
    odometry: how far the robot's `odom` was from the truth over the request.
    localization: how far its localization's base in the map was (none for the truth
    ablation). placement: how far perception put the artifacts it saw in the map.
    """

    world: str
    world_seed: int
    scenario: str
    object: str = ""
    person: str = ""
    truth_object: str = ""
    truth_person: str = ""
    truth_match_m: tuple[float, float] = (math.nan, math.nan)
    distance_m: float = math.nan
    outcome: str = "failed"
    truth_reason: str = ""
    mission_state: str = ""
    mission_reason: str = ""
    mission_detail: str = ""
    agree: bool = False
    stage_reached: str = ""
    last_behaviour: str = ""
    stages_passed: list[str] = msgspec.field(default_factory=list)
    stage_times_s: dict[str, float] = msgspec.field(default_factory=dict)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    rtf: float = 0.0
    setup_wall_s: float = 0.0
    contacts_static: int = 0
    contacts: list[str] = msgspec.field(default_factory=list)
    lockstep_stalls: int = -1
    drops: int = 0
    services_down: list[str] = msgspec.field(default_factory=list)
    recording: str = ""
    logs: str = ""
    troubles: dict[str, list[str]] = msgspec.field(default_factory=dict)
    #: Sim times (s) at which the evaluating client's own link lapsed and the watch went
    #: on (`common.lifelines.OwnLink`): statuses may be missing there, the digest differ.
    watch_lapses: list[float] = msgspec.field(default_factory=list)
    picture: str = ""
    failure_frames: list[str] = msgspec.field(default_factory=list)
    error: str = ""
    digest: str = ""
    #: The robot's own estimate of its base against the truth (`EstimateErrors.figures`).
    odometry: dict[str, float] = msgspec.field(default_factory=dict)
    #: Its localization against the truth (`LocalizationErrors.figures`).
    localization: dict[str, float] = msgspec.field(default_factory=dict)
    #: Perception's placement of artifacts in the map (`PlacementErrors.figures`).
    placement: dict[str, float] = msgspec.field(default_factory=dict)
    #: With `--map explored`: the exploration before the request (its outcome, times) and
    #: its map judged from truth (`explored.score_entities`, `trial_explore.score_map`).
    exploration: dict[str, Any] = msgspec.field(default_factory=dict)

    @property
    def succeeded(self) -> bool:
        return self.outcome == "succeeded"

    @property
    def failure(self) -> str:
        """One sentence on why this world failed ("" when it succeeded)."""
        if self.succeeded:
            return ""
        if self.error:
            return self.error
        down = f" (down: {', '.join(self.services_down)})" if self.services_down else ""
        mission = self.mission_reason or self.mission_state or "no status"
        detail = f": {self.mission_detail}" if self.mission_detail else ""
        where = self.last_behaviour or "-"
        said = f"mission {self.mission_state} in {where} ({mission}{detail})"
        return f"{said}; {self.truth_reason}{down}"


@dataclass
class MissionRecord:
    """What was seen of one request on a live stack (`bench.eval.run.watch_mission`).

    start_ns: sim time when the request went out. end_ns: sim time when watching stopped.
    changes: the request's status changes (`transitions`). events: every world event
    seen from the request on. ended: why watching stopped early ("" when the mission
    reached a final state): a timeout, a stopped clock.
    """

    request: MissionRequest
    start_ns: int
    end_ns: int = 0
    changes: list[MissionStatus] = field(default_factory=list)
    events: list[WorldEvent] = field(default_factory=list)
    ended: str = ""
    wall_s: float = 0.0
    #: The sim times (s) at which this watcher's own link lapsed and came back
    #: (`common.lifelines.OwnLink`): what it heard meanwhile may lack a status or two.
    lapses: list[float] = field(default_factory=list)
    #: The base every `TRAJECTORY_EVERY_NS` of sim time from the request on: (stamp_ns,
    #: x, y, z, qx, qy, qz, qw) from the sim's truth (`state_truth`).
    trajectory: list[tuple[float, ...]] = field(default_factory=list)
    #: The robot's odometry against the truth over the request (`EstimateErrors`).
    odometry: dict[str, Any] = field(default_factory=dict)
    #: Its localization against the truth over the request (`LocalizationErrors`).
    localization: dict[str, Any] = field(default_factory=dict)
    #: Perception's artifacts in the map against the truth, before the pick.
    placement: dict[str, Any] = field(default_factory=dict)


#: The trajectory's sample period in a `MissionRecord` (10 Hz).
TRAJECTORY_EVERY_NS = 100_000_000


def run_digest(record: MissionRecord) -> str:
    """A fingerprint of one run: its status timeline (every change, exactly as published)
    and the base's trajectory at 10 Hz up to the last change, bit for bit. Two runs of
    the same seed must print the same digest; one differing sample changes it."""
    until = record.changes[-1].stamp_ns if record.changes else record.end_ns
    body = {  # the request's id is the client's name for it: not part of the run
        "request": [record.request.object, record.request.person],
        "changes": [{**msgspec.to_builtins(c), "request_id": ""} for c in record.changes],
        "trajectory": [p for p in record.trajectory if p[0] <= until],
    }
    return hashlib.sha256(msgspec.json.encode(body)).hexdigest()[:16]


def evaluate(result: WorldResult, record: MissionRecord, world: WorldDescription) -> WorldResult:
    """Fill `result` (world, seed, targets and truth ids already set) from a record."""
    verdict = (
        judge(result.truth_object, result.truth_person, record.events)
        if result.truth_object and result.truth_person
        else Verdict(False, "the request's targets match nothing in the world")
    )
    final = record.changes[-1] if record.changes else None
    mission_ok = final is not None and final.state == "succeeded"
    contacts = static_contacts(record.events, world)
    sim_s = max(0, record.end_ns - record.start_ns) / 1e9
    behaviours = [c.behaviour for c in record.changes if c.behaviour]
    result.outcome = "succeeded" if verdict.success else "failed"
    result.truth_reason = verdict.reason
    result.mission_state = final.state if final else ""
    if record.ended and not (final is not None and final.state in TERMINAL):
        # Watching stopped before a final status: why (a timeout, a stopped clock, a
        # dependency lost) is the reason, "dependency_lost: mission is gone" split so.
        reason, _, detail = record.ended.partition(": ")
        result.mission_reason, result.mission_detail = (
            (reason, detail) if detail and " " not in reason else (record.ended, "")
        )
    else:
        result.mission_reason = (final.reason if final else "") or record.ended
        result.mission_detail = final.detail if final else ""
    result.agree = mission_ok == verdict.success
    result.stage_reached = stage_reached(record.changes)
    result.last_behaviour = behaviours[-1] if behaviours else ""
    result.stages_passed = stages_passed(record.changes)
    times = stage_times(record.changes, record.end_ns)
    result.stage_times_s = {k: round(v, 3) for k, v in times.items()}
    result.sim_time_s = round(sim_s, 3)
    result.wall_time_s = round(record.wall_s, 2)
    result.watch_lapses = list(record.lapses)
    result.rtf = round(sim_s / record.wall_s, 3) if record.wall_s > 0 else 0.0
    result.contacts_static = len(contacts)
    result.contacts = [f"{c.body}-{c.other}@{c.stamp_ns / 1e9:.1f}s" for c in contacts]
    result.drops = len(events_of(record.events, "drop"))
    result.digest = run_digest(record)
    result.odometry = dict(record.odometry)
    result.localization = dict(record.localization)
    result.placement = dict(record.placement)
    return result
