"""`dume eval --shift --worlds W --requests M --seed S`: a shift of requests per world on
one stack, in a hall that changes between them, judged from the simulator's truth.

World i is seed S + i. Each world gets one stack, started as `dume eval` starts it (the
world's saved map; a world with none explored first; `--map truth` the ablation), that
serves M requests one after another:

- **the request** (`shift_request`, seeded by the world seed and the request's number):
  a mapped artifact that still stands where the map has it (truth: within
  `MATCH_M`, not handed over earlier in the shift) for a mapped person other than the last
  request's, one the map keeps (`firm_people`: seeded, or made from at least the map's
  `drop_below_observations` detections: hall seed 3's shift asked for person_7, made
  from two, which the map deleted as a false entry while the robot fetched the bottle);
  one in `CLASS_EVERY` asks by class ("a can": the mission picks the nearest mapped one);
- **the changing hall** (`--changes`, on by default): before each request after the
  first, somebody moves an artifact not handed over yet (the requested one half the
  time, when it can be) onto another support (`services.sim.world.new_place`), through
  the sim's hook (`dume/world/artifact_command`), and half the time somebody leaves the
  hall's trolley in an aisle (`leave_trolley`: `services.sim.world.aisle_spot`, clear of
  the robot, the people and the artifacts, every goal still reachable round it;
  `dume/world/movable_command`), where the robot's map has floor; with `--bystanders`
  the people walk their routes past the robot all shift long;
- **what was handed over is taken away**: before the next request each person who took
  an object carries it off (`put_away`: out of the hall, `ArtifactCommand.away`), as a
  worker takes a part to where it is used; the sim's hand holds one thing at a time, and
  a person still holding the last one could take nothing more (hall seed 3's shift:
  person_2 held bottle_2 from request 1, and request 3's bottle was held out to them for
  60 s);
- **the worker asked for answers** (`bench.eval.answer`): when the mission asks for the
  person it cannot find ("asking for person_5: please come to the robot"), the request's
  truth person, within earshot and with a straight way to the robot, walks over and
  stands in front of it (people commands stamped after the ask); what the mission makes
  of who came is its own (`LookForPerson`);
- **slips** (`--slips F`, the fraction of requests): a knock on the object the robot
  carries, 3 s into the carry (`Knock`, the sim's push hook on the artifact): recovered
  when the request still succeeded, else the mission's reason says why;
- **time**: the move and the request go out stamped ahead of their sim time (the move
  `MOVE_AFTER_S` after the last request ended, the request `REQUEST_AFTER_S`:
  `MissionRequest.at_ns`), so a lockstep shift repeats as one request does.

Each request is judged as `dume eval` judges one (`bench.eval.judge.evaluate`) against
the truth of the moment: the artifacts where the moves put them; the requested person is
the one nearest the map's estimate of them where `dume/world/people` had everyone when
the map last saw them (`whom`: walking people are far from a stale estimate). A class
request succeeded when the requested person took any artifact of that class. Over the
whole shift the robot's separation from every person is judged from truth
(`SeparationWatch`: the least separation, the robot's speed then, and the speed and
separation monitor's own rule: moving towards a person closer than the protective
separation of both true speeds is a violation). The report is `dume eval`'s, one row per
request, with the shift's separation figures and moves added.
"""

from __future__ import annotations

import argparse
import bisect
import json
import math
import os
import random
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import numpy as np

from bench.eval.answer import Answer
from bench.eval.evaluate import (
    START_TIMEOUT_S,
    STOP_TIMEOUT_S,
    ExplorationFailed,
    _say,
    _stage_line,
    explore_first,
    map_source,
    map_start_text,
    scenario_of,
    world_overrides,
)
from bench.eval.judge import MissionRecord, TruthMatch, WorldResult, evaluate
from bench.eval.judge import truth_person as match_person
from bench.eval.report import json_safe, write_report
from bench.eval.run import (
    Progress,
    read_map,
    read_world,
    request_result,
    sigterm_interrupts,
    watch_mission,
)
from bench.eval.shift_plots import ShiftPlots, map_accuracy
from bench.eval.targets import Pair, TargetError
from bench.separation import SeparationWatch, truth_separation
from common.bus import BusError, Fifo
from common.config import ConfigError, load_config, resolve
from common.geometry import yaw_of_quat_xyzw
from common.keys import (
    WORLD_ARTIFACT_COMMAND,
    WORLD_MOVABLE_COMMAND,
    WORLD_PEOPLE,
    WORLD_PEOPLE_COMMAND,
    WORLD_PUSH,
)
from common.messages import PayloadError
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.semantic_map import MapEntity
from common.messages.sim import (
    ArtifactCommand,
    Clock,
    HandoverTaken,
    MovableCommand,
    PeopleTruth,
    PersonCommand,
    Push,
    SimStats,
    StateTruth,
)
from common.messages.world import WorldDescription
from common.runfiles import write_whole
from deploy.demo import SERVICES
from deploy.runs import shown
from deploy.stack import ProcessStack
from services.semantic_map.store import database_path, remove_database
from services.sim.world import aisle_spot, new_place

#: m: a mapped artifact stands for the truth artifact nearest to it within this.
MATCH_M = 0.3
#: m: a mapped person stands for the truth person nearest to them within this.
PERSON_MATCH_M = 1.0
#: ns between the people samples kept for the whole shift (who a mapped person is).
HISTORY_EVERY_NS = 250_000_000
#: Every this many requests, one asks by class.
CLASS_EVERY = 3
#: A slip: the knock's force sideways (N), how long (s), how long after the carry began (s).
KNOCK_N = 20.0
KNOCK_S = 0.1
KNOCK_AFTER_S = 3.0
#: Sim seconds after the last request ended that the move, then the request, take effect.
#: Wide enough that both reach the sim ahead of their time while the harness reads the
#: map and the world between requests (1 s and 2.5 s came 0.2-0.25 s late at rtf 0.35).
MOVE_AFTER_S = 5.0
REQUEST_AFTER_S = 6.0


# -- the request ----------------------------------------------------------------------------


def present_artifacts(
    artifacts: Sequence[MapEntity], where: dict[str, tuple[float, float, float]], gone: set[str]
) -> list[tuple[MapEntity, str]]:
    """The mapped artifacts that still stand where the map has them: (entity, the truth
    artifact it stands for), the truth one of the same class, not `gone`, within
    `MATCH_M` on the floor; sorted by map id."""
    out = []
    for e in sorted(artifacts, key=lambda e: e.id):
        if e.missing_since_ns is not None:
            continue
        best, best_d = "", MATCH_M
        for tid, (x, y, _) in where.items():
            d = math.hypot(x - e.position_in_world[0], y - e.position_in_world[1])
            if tid not in gone and tid.split("_")[0] == e.class_name and d <= best_d:
                best, best_d = tid, d
        if best:
            out.append((e, best))
    return out


def shift_request(
    present: Sequence[tuple[MapEntity, str]],
    people: Sequence[MapEntity],
    seed: int,
    k: int,
    last_person: str = "",
) -> tuple[Pair, str]:
    """Request k of world `seed`'s shift: the pair, and the truth artifact asked for (""
    for a class request). Raises TargetError when nothing can be asked."""
    folks = sorted((p for p in people if p.missing_since_ns is None), key=lambda p: p.id)
    if not present or not folks:
        raise TargetError(f"the map holds {len(present)} present artifacts, {len(folks)} people")
    rng = random.Random(seed * 1000 + k)
    entity, truth = rng.choice(list(present))
    others = [p for p in folks if p.id != last_person] or folks
    who = rng.choice(others)
    if k % CLASS_EVERY == CLASS_EVERY - 1:
        return Pair(entity.class_name, who.id, math.nan), ""
    d = math.dist(entity.position_in_world[:2], who.position_in_world[:2])
    return Pair(entity.id, who.id, d), truth


class Follow:
    """The truth samples of a shift, paired by stamp: each people sample (the lidar's
    rate) with the base's truth of the same stamp (`state_truth`, at a multiple of it);
    a people sample whose base has not come yet waits for the next `drain`. Every
    `HISTORY_EVERY_NS` a people sample is kept for the whole shift (`people_at`)."""

    def __init__(self, people: Fifo[PeopleTruth], base: Fifo[StateTruth], watch: SeparationWatch):
        self.people, self.base, self.watch = people, base, watch
        self._people: list[PeopleTruth] = []
        self._base: dict[int, StateTruth] = {}
        self.history: list[PeopleTruth] = []
        self.bases: list[StateTruth] = []  # the base's, kept as the people's are

    def people_at(self, t_ns: int) -> PeopleTruth | None:
        """The kept people sample nearest to sim time `t_ns` (None before any)."""
        return _nearest(self.history, t_ns)

    def base_at(self, t_ns: int) -> StateTruth | None:
        """The kept base sample nearest to sim time `t_ns` (None before any)."""
        return _nearest(self.bases, t_ns)

    def drain(self) -> None:
        fresh = list(self.people.drain())
        for sample in fresh:
            _keep(self.history, sample)
        self._people.extend(fresh)
        for b in self.base.drain():
            self._base[b.stamp_ns] = b
            _keep(self.bases, b)
        left: list[PeopleTruth] = []
        for sample in self._people:
            base = self._base.get(sample.stamp_ns)
            if base is None:
                left.append(sample)
            else:
                self.watch.add(base, sample)
        newest = max(self._base, default=-1)
        self._people = [p for p in left if p.stamp_ns > newest]  # its base never came
        oldest = min((p.stamp_ns for p in self._people), default=newest)
        self._base = {t: b for t, b in self._base.items() if t >= oldest}


# -- the shift ------------------------------------------------------------------------------


Stamped = TypeVar("Stamped", PeopleTruth, StateTruth)


def _keep(kept: list[Stamped], sample: Stamped) -> None:
    """Keep `sample` when it is `HISTORY_EVERY_NS` or more after the last one kept."""
    if not kept or sample.stamp_ns - kept[-1].stamp_ns >= HISTORY_EVERY_NS:
        kept.append(sample)


def _nearest(kept: list[Stamped], t_ns: int) -> Stamped | None:
    """The kept sample nearest to sim time `t_ns` (None before any)."""
    if not kept:
        return None
    k = bisect.bisect_left([h.stamp_ns for h in kept], t_ns)
    return min(kept[max(0, k - 1) : k + 1], key=lambda h: abs(h.stamp_ns - t_ns))


@dataclass
class Truth:
    """The world as the shift has changed it: where each artifact stands now, which were
    handed over, where the people are."""

    world: WorldDescription
    where: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    gone: set[str] = field(default_factory=set)
    moves: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.where = {a.id: a.position for a in self.world.artifacts}

    def now(self, people: PeopleTruth | None) -> WorldDescription:
        """The world description with the artifacts and people where they are now."""
        arts = tuple(
            msgspec.structs.replace(a, position=self.where[a.id])
            for a in self.world.artifacts
            if a.id not in self.gone
        )
        folks = self.world.people
        if people is not None:
            at = {p.id: p.position for p in people.people}
            folks = tuple(msgspec.structs.replace(p, position=at.get(p.id, p.position))
                          for p in folks)  # fmt: skip
        return msgspec.structs.replace(self.world, artifacts=arts, people=folks)


def stands_for(who: MapEntity, follow: Follow, truth: Truth) -> TruthMatch | None:
    """The truth person a mapped person stands for: the one nearest to the map's estimate
    where the people were when the map last saw them (`last_seen_ns`), not at the
    request (a walking person is metres from their last sighting: 4.5 m on hall seed 0's
    shift, and the request was judged for whoever stood nearest the stale estimate). A
    saved map's person not seen yet this run is judged where the people stood when the
    run began: where the exploration that made the map left them. None: no sample then."""
    if not who.last_seen_ns:
        return match_person(truth.now(None), who.position_in_world[:2])
    then = follow.people_at(who.last_seen_ns)
    return None if then is None else match_person(truth.now(then), who.position_in_world[:2])


def real_people(
    people: Sequence[MapEntity], follow: Follow, truth: Truth
) -> tuple[list[MapEntity], list[str]]:
    """The mapped people who stand for somebody (`stands_for` within `PERSON_MATCH_M`),
    and the ids of those who stand for nobody (ghosts: a request for them asks for
    nobody, and is not drawn)."""
    real, ghosts = [], []
    for who in people:
        match = stands_for(who, follow, truth)
        if match is not None and match.distance_m <= PERSON_MATCH_M:
            real.append(who)
        else:
            ghosts.append(who.id)
    return real, ghosts


def firm_people(people: Sequence[MapEntity], least: int) -> list[MapEntity]:
    """Those of `people` the map keeps: seeded or imported, or made from at least `least`
    detections (the map's `drop_below_observations`; fewer, it deletes an entry its looks
    miss)."""
    return [p for p in people if p.source != "perception" or p.observations >= least]


def whom(
    result: WorldResult, person: str, people: list[MapEntity], follow: Follow, truth: Truth
) -> None:
    """The request's truth person: the one the mapped person stands for (`stands_for`)."""
    who = next((p for p in people if p.id == person), None)
    match = None if who is None else stands_for(who, follow, truth)
    if match is not None:
        result.truth_person = match.id
        result.truth_match_m = (result.truth_match_m[0], round(match.distance_m, 3))


def class_verdict(result: WorldResult, record: MissionRecord, class_name: str) -> None:
    """A class request succeeded when the requested person took any artifact of it."""
    took = [
        e for e in record.events
        if isinstance(e, HandoverTaken) and e.person_id == result.truth_person
        and e.object_id.split("_")[0] == class_name
    ]  # fmt: skip
    if took:
        result.outcome = "succeeded"
        result.truth_object = took[0].object_id
        result.truth_reason = f"{took[0].person_id} took {took[0].object_id} (a {class_name})"
    else:
        what = [f"{e.person_id} took {e.object_id}" for e in record.events
                if isinstance(e, HandoverTaken)]  # fmt: skip
        result.truth_reason = (
            f"{result.truth_person or 'the person asked'} took no {class_name} "
            f"({'; '.join(what) or 'no handover happened'})"
        )
    result.agree = (result.mission_state == "succeeded") == result.succeeded


def run_shift_world(
    args: argparse.Namespace, seed: int, out: list[WorldResult], stopped: list[dict[str, Any]]
) -> dict[str, Any]:
    """One world's shift, start to teardown: its requests' results appended to `out`;
    the world's shift figures (separation, moves). Interrupted, the figures so far go to
    `stopped` (completed as the teardown ends) before the interrupt goes on."""
    scenario = scenario_of(args)
    map_name = f"shift-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{seed}"
    overrides = world_overrides(args, seed, map_name)
    tracing = bool(getattr(args, "trace_people", False))  # for `dume bench people-ids`
    traced = resolve(args.out) / f"people-seed-{seed}.trace"  # the map's people input
    truth_path = traced.with_name(f"people-truth-seed-{seed}.msgpack")  # and the truth's
    if tracing:
        overrides["semantic_map.people_trace"] = str(traced)
    stack = ProcessStack(list(SERVICES), overrides)
    watch = SeparationWatch(truth_separation(overrides))
    cfg = load_config(overrides)
    plots = ShiftPlots(cfg.navigation.people.slow_radius_m)
    figures: dict[str, Any] = {"world_seed": seed, "map_accuracy": []}
    rng = np.random.default_rng(seed)
    truth: Truth | None = None
    step = "start the stack"
    try:
        stack.start(timeout_s=START_TIMEOUT_S)
        bus, keys = stack.bus, stack.keys
        stats = bus.latest(keys.sim_stats, SimStats)
        follow = Follow(bus.fifo(WORLD_PEOPLE, PeopleTruth, maxlen=1 << 16),
                        bus.fifo(keys.state_truth, StateTruth, maxlen=1 << 19), watch)  # fmt: skip
        people_now = bus.latest(WORLD_PEOPLE, PeopleTruth)
        mover = bus.publisher(WORLD_ARTIFACT_COMMAND, ArtifactCommand, "control")
        trolleys = bus.publisher(WORLD_MOVABLE_COMMAND, MovableCommand, "control")
        base_now = bus.latest(keys.state_truth, StateTruth)
        trolley_rng = np.random.default_rng([seed, TROLLEY_STREAM])  # the moves' draws unchanged
        pusher = bus.publisher(WORLD_PUSH, Push, "control")
        walkers = bus.publisher(WORLD_PEOPLE_COMMAND, PersonCommand, "control")
        how, path = map_source(args.map, args.world, seed)
        gated = True
        if how == "explore":
            step = "explore the world"
            e = explore_first(stack, read_world(bus), seed, path)
            figures["exploration"] = e
            gated = False
            if e["outcome"] != "succeeded":
                raise ExplorationFailed(f"it ended {e['outcome']}: {e['reason']}")
        truth = Truth(read_world(bus))
        last_person, end_ns = "", 0
        handed: list[HandoverTaken] = []
        for k in range(args.requests):
            step = f"make request {k + 1}"
            follow.drain()
            arts, people = read_map(bus)
            there = {a: p for a, p in truth.where.items() if a not in truth.gone}
            within, current = map_accuracy(arts, there)
            plots.accuracy.append((end_ns / 1e9, within, current))
            figures["map_accuracy"].append({"request": k + 1, "t_s": round(end_ns / 1e9, 1),
                                            "within_10cm": round(within, 3),
                                            "current": round(current, 3)})  # fmt: skip
            present = present_artifacts(arts, truth.where, truth.gone)
            real, ghosts = real_people(people, follow, truth)
            if ghosts:
                figures.setdefault("people_ghosts", []).append({"request": k + 1, "ids": ghosts})
            firm = firm_people(real, cfg.semantic_map.drop_below_observations)
            pair, asked = shift_request(present, firm or real, seed, k, last_person)
            at_ns = None
            if not gated:
                at_ns = end_ns + round(REQUEST_AFTER_S * 1e9)
                put_away(truth, mover, handed, end_ns + round(MOVE_AFTER_S * 1e9))
                if args.changes:
                    move(truth, mover, rng, asked, end_ns + round(MOVE_AFTER_S * 1e9))
                    leave_trolley(truth, trolleys, trolley_rng, base_now.get(),
                                  people_now.get(), end_ns + round(MOVE_AFTER_S * 1e9))  # fmt: skip
            result = WorldResult(world=args.world, world_seed=seed, scenario=scenario)
            world_now = truth.now(people_now.get())
            request_result(result, pair, arts, people, world_now)
            whom(result, pair.person, people, follow, truth)
            if asked:
                result.truth_object = asked
            result.object = f"{pair.object} (#{k + 1})"
            request = MissionRequest(request_id=f"shift-{seed}-{k + 1}", object=pair.object,
                                     person=pair.person, at_ns=at_ns)  # fmt: skip
            step = f"run request {k + 1}"
            knock = Knock(pusher, asked, rng.random() < args.slips, _stage_line(seed))
            statuses = bus.fifo(keys.mission_status, MissionStatus, maxlen=1 << 14)
            answer = Answer(statuses, follow, walkers, truth.world.occupancy, request.request_id,
                            pair.person, result.truth_person)  # fmt: skip

            record = watch_mission(bus, keys, request, args.timeout,
                                   both(knock.on_progress, answer.on_progress),
                                   start_gate=gated)  # fmt: skip
            statuses.undeclare()
            for line in answer.said:
                _say(f"    {line}")
            if answer.said:
                figures.setdefault("answers", []).append({"request": k + 1,
                                                          "said": answer.said})  # fmt: skip

            gated = False
            plots.changes.extend(record.changes)
            evaluate(result, record, world_now)
            if not asked:
                class_verdict(result, record, pair.object)
            if knock.at_ns:  # a slip: recovered when it still succeeded, else said why
                figures.setdefault("knocks", []).append({
                    "request": k + 1, "object": asked, "at_s": knock.at_ns / 1e9,
                    "dropped": result.drops, "outcome": result.outcome,
                    "mission": f"{result.mission_state} {result.mission_reason}".strip(),
                })  # fmt: skip
            handed = [h for h in record.events if isinstance(h, HandoverTaken)]
            truth.gone |= {h.object_id for h in handed}
            end_ns = max(record.end_ns, (record.changes[-1].stamp_ns if record.changes else 0))
            last_person = pair.person
            out.append(result)
            if tracing:  # replayable while the shift goes on
                follow.drain()
                keep_people_truth(follow, truth_path)
            ok = sum(r.succeeded for r in out)
            _say(
                f"  [{seed} #{k + 1}] {pair.object} → {pair.person}: {result.outcome} "
                f"(mission {result.mission_state or '-'}) sim {result.sim_time_s:.1f} s | "
                f"{ok}/{len(out)} succeeded"
                + (f" | {result.failure}" if not result.succeeded else "")
            )
        follow.drain()
        if (last := stats.get()) is not None:
            figures["lockstep_stalls"] = last.stalls
    except (BusError, PayloadError, TargetError, ExplorationFailed) as exc:
        figures["error"] = f"could not {step}: {exc}"
        _say(f"  [{seed}] {figures['error']}")
    except KeyboardInterrupt:  # the report keeps this world's figures so far
        figures["error"] = f"interrupted during: {step}"
        stopped.append(figures)
        raise
    finally:
        stack.stop(timeout_s=STOP_TIMEOUT_S)
        remove_database(database_path(stack.config.semantic_map, map_name))
        figures["separation"] = watch.figures()
        figures["moves"] = list(truth.moves) if truth is not None else []
        plots_path = resolve(args.out) / f"shift-seed-{seed}.rrd"
        plots_path.parent.mkdir(parents=True, exist_ok=True)
        plots.write(plots_path, watch.series)
        figures["plots"] = str(plots_path)
        figures["logs"] = shown(stack.run_dir)
        if tracing and truth is not None:
            follow.drain()
            keep_people_truth(follow, truth_path)
            figures["people_trace"] = [shown(traced), shown(truth_path),
                                       shown(base_truth_path(truth_path))]  # fmt: skip
    return figures


def both(first: Progress, second: Progress) -> Progress:
    """One progress callback that calls `first`, then `second`."""

    def progress(status: MissionStatus | None, clock: Clock, changed: bool) -> None:
        first(status, clock, changed)
        second(status, clock, changed)

    return progress


def keep_people_truth(follow: Follow, path: Path) -> None:
    """The shift's truth people so far into `path`, beside the map's people trace (for
    `dume bench people-ids`), and the base's (`base-truth-seed-<s>.msgpack`, the same
    stamps: where the robot stood as each person passed, for reading a hold in the logs)."""
    write_whole(path, msgspec.msgpack.encode(follow.history))
    write_whole(base_truth_path(path), msgspec.msgpack.encode(follow.bases))


def base_truth_path(people_truth: Path) -> Path:
    """The base's truth trace beside the people's truth trace `people_truth`."""
    return people_truth.with_name(people_truth.name.replace("people-truth", "base-truth"))


class Knock:
    """A slip (`--slips`, the fraction of requests): once the request's status enters
    `bring_to_user` (the robot carries its object), a knock on the object asked for
    (`KNOCK_N` sideways for `KNOCK_S`, `KNOCK_AFTER_S` later; a request by class has no
    object known to knock). `on_progress` also prints the stage lines."""

    def __init__(self, pusher: Any, target: str, armed: bool, line: Any) -> None:
        self.pusher, self.target, self.armed, self.line = pusher, target, armed, line
        self.at_ns = 0

    def on_progress(self, status: MissionStatus | None, clock: Clock, changed: bool) -> None:
        self.line(status, clock, changed)
        if not (self.armed and self.target and changed and status is not None):
            return
        if status.behaviour == "bring_to_user" and not self.at_ns:
            self.at_ns = status.stamp_ns + round(KNOCK_AFTER_S * 1e9)
            self.pusher.put(Push(stamp_ns=self.at_ns, force_in_world=(0.0, KNOCK_N, 0.0),
                                 duration_s=KNOCK_S, target=self.target))  # fmt: skip
            _say(f"    knocked {self.target} at {self.at_ns / 1e9:.1f} s")


def move(truth: Truth, mover: Any, rng: np.random.Generator, asked: str, at_ns: int) -> None:
    """Somebody moves an artifact before the next request (the asked one half the time):
    onto another support, sent ahead of its time; recorded in `truth`."""
    left = sorted(a for a in truth.where if a not in truth.gone)
    if not left:
        return
    pick = asked if asked and rng.random() < 0.5 else left[int(rng.integers(len(left)))]
    surface = next((a.surface_id for a in truth.world.artifacts if a.id == pick), "")
    taken = [p[:2] for a, p in truth.where.items() if a != pick and a not in truth.gone]
    spot = new_place(truth.world, pick, rng, taken, surface)
    if spot is None:
        return
    position, yaw, on = spot
    mover.put(ArtifactCommand(stamp_ns=at_ns, artifact_id=pick, position=position, yaw=yaw))
    truth.where[pick] = position
    truth.moves.append(f"{pick} onto {on} at {at_ns / 1e9:.1f} s")
    _say(f"    moved {pick} onto {on} (at {at_ns / 1e9:.1f} s)")


def put_away(truth: Truth, mover: Any, taken: Sequence[HandoverTaken], at_ns: int) -> None:
    """Whoever took an object in the last request carries it off, out of the hall (sent
    ahead of its time; recorded in `truth`): their hand is free for the next one."""
    for h in taken:
        mover.put(ArtifactCommand(stamp_ns=at_ns, artifact_id=h.object_id, away=True))
        truth.moves.append(f"{h.object_id} taken away by {h.person_id} at {at_ns / 1e9:.1f} s")
        _say(f"    {h.person_id} took {h.object_id} away (at {at_ns / 1e9:.1f} s)")


#: The trolley's draws come from their own stream of the world's seed, and it is left in
#: an aisle before this share of the requests after the first.
TROLLEY_STREAM = 7
TROLLEY_SHARE = 0.5


def leave_trolley(
    truth: Truth,
    mover: Any,
    rng: np.random.Generator,
    base: StateTruth | None,
    people: PeopleTruth | None,
    at_ns: int,
) -> None:
    """Somebody leaves the hall's trolley in an aisle before the next request (half the
    time; a world with no movable, none): a spot clear of the robot, the people and the
    artifacts where they are now, with every goal still reachable round it
    (`aisle_spot`), sent ahead of its time; recorded in `truth`."""
    if not truth.world.movables or base is None or rng.random() >= TROLLEY_SHARE:
        return
    trolley = truth.world.movables[0].id
    now = truth.now(people)
    x, y, _ = base.base_position_in_world
    clear = [p.position[:2] for p in now.people] + [a.position[:2] for a in now.artifacts]
    pose = (x, y, yaw_of_quat_xyzw(base.base_orientation_xyzw))
    spot = aisle_spot(now, trolley, rng, pose, clear)
    if spot is None:
        return
    sx, sy, yaw = spot
    mover.put(MovableCommand(stamp_ns=at_ns, movable_id=trolley, position=(sx, sy), yaw=yaw))
    truth.moves.append(f"{trolley} left at ({sx:.1f}, {sy:.1f}) at {at_ns / 1e9:.1f} s")
    _say(f"    left {trolley} in an aisle at ({sx:.1f}, {sy:.1f}) (at {at_ns / 1e9:.1f} s)")


def run_shift(args: argparse.Namespace) -> int:
    """`dume eval --shift`: every world's shift, the report after each world."""
    out = resolve(args.out)
    seeds = [args.seed + i for i in range(args.worlds)]
    results: list[WorldResult] = []
    shifts: list[dict[str, Any]] = []
    wall0 = time.perf_counter()
    stopped = ""

    def settings() -> dict[str, Any]:
        return {
            "world": args.world,
            "world seeds": f"{seeds[0]}..{seeds[-1]}" if seeds else "-",
            "scenario": scenario_of(args),
            "shift": f"{args.requests} requests per world on one stack, one in {CLASS_EVERY} "
            f"by class; {'an artifact moved before each' if args.changes else 'no moves'}; "
            f"{args.slips:.0%} of the carries knocked",
            "map start": map_start_text(args.map),
            "timeout per request": f"{args.timeout:.0f} s sim",
            "extra settings": ", ".join(args.set) or "none",
            "wall time": f"{time.perf_counter() - wall0:.0f} s",
            **({"stopped early": stopped} if stopped else {}),
        }

    def report() -> dict[str, Any]:
        summary = write_report(out, settings(), results)
        write_shift_section(out, shifts)
        return summary

    _say(
        f"dume eval --shift: {len(seeds)} {args.world} worlds × {args.requests} requests, out {out}"
    )
    summary: dict[str, Any] = {}
    with sigterm_interrupts():
        try:
            for seed in seeds:
                shifts.append(run_shift_world(args, seed, results, shifts))
                summary = report()
        except KeyboardInterrupt:
            stopped = "interrupted"
        except ConfigError as exc:
            stopped = f"the settings no longer load (changed during the run?): {exc}"
    if stopped:
        summary = report()
    print(json.dumps(json_safe({**summary, "shifts": shifts, "out": str(out), "stopped": stopped})))
    if stopped:
        return 130 if stopped == "interrupted" else 2
    return 0 if results and not any("error" in s for s in shifts) else 1


def _part(title: str, items: list[str]) -> list[str]:
    """A titled list of the report: a blank line, the title, a blank line, the items."""
    return ["", title, "", *items]


def write_shift_section(out: Path, shifts: Sequence[dict[str, Any]]) -> None:
    """The shift's own figures after the report: separation per world, the moves."""
    lines = [
        "",
        "## The shift",
        "",
        "Separation from people, judged from truth over the whole shift (the footprint's "
        "distance to each person; a violation: the robot moving towards a person closer "
        "than the protective separation of both true speeds, the monitor's own rule).",
        "",
        "| seed | truth samples | violations | least margin, m | closest, m (who) "
        "| robot speed then, m/s | moves | error |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in shifts:
        sep = s.get("separation", {})
        lines.append(
            f"| {s['world_seed']} | {sep.get('samples', 0)} | {sep.get('violations', 0)} | "
            f"{sep.get('least_margin_m', math.nan)} | {sep.get('closest_m', math.nan)} "
            f"({sep.get('closest_person', '-')}) | {sep.get('speed_at_closest_mps', math.nan)} | "
            f"{len(s.get('moves', []))} | {s.get('error', '')} |"
        )
    moves = [f"- seed {s['world_seed']}: {m}" for s in shifts for m in s.get("moves", [])]
    if moves:
        lines += _part("Moves (truth):", moves)
    kept = [
        f"- seed {s['world_seed']} t={v['t_s']} s: {v['person']} at {v['d_m']} m, S_p "
        f"{v['s_p_m']} m, robot {v['v_robot_mps']} m/s towards them, they "
        f"{v['v_person_mps']} m/s towards it"
        for s in shifts for v in s.get("separation", {}).get("violations_kept", [])
    ]  # fmt: skip
    if kept:
        lines += _part("Separation violations (the first of each world, from truth):", kept)
    accuracy = [
        f"| {s['world_seed']} | {a['request']} | {a['t_s']} | {a['within_10cm']:.0%} "
        f"| {a['current']:.0%} |"
        for s in shifts for a in s.get("map_accuracy", [])
    ]  # fmt: skip
    if accuracy:
        lines += [
            "", "The map's accuracy before each request (truth: the artifacts there that it "
            "has within 10 cm; its entries that stand where an artifact of their class is):",
            "", "| seed | request | sim time, s | within 10 cm | current |",
            "|---|---|---|---|---|", *accuracy,
        ]  # fmt: skip
    plots = [f"- seed {s['world_seed']}: `{Path(s['plots']).name}`" for s in shifts
             if s.get("plots")]  # fmt: skip
    if plots:
        lines += _part("Plots (rerun recordings: the stage by time, the separation with S_p "
                       "and the slow zone, the map's accuracy):", plots)  # fmt: skip
    knocks = [
        f"- seed {s['world_seed']} request {k['request']}: {k['object']} knocked at "
        f"{k['at_s']:.1f} s; drops {k['dropped']}; {k['outcome']} (mission {k['mission']})"
        for s in shifts for k in s.get("knocks", [])
    ]  # fmt: skip
    if knocks:
        lines += _part("Slips (a knock on what the robot carried):", knocks)
    ghosts = [
        f"- seed {s['world_seed']} request {g['request']}: {', '.join(g['ids'])}"
        for s in shifts for g in s.get("people_ghosts", [])
    ]  # fmt: skip
    if ghosts:
        said = (f"The map's people who stood for nobody (truth: no person within "
                f"{PERSON_MATCH_M:g} m when last seen; never asked for):")  # fmt: skip
        lines += _part(said, ghosts)
    traces = [f"- seed {s['world_seed']}: {', '.join(s['people_trace'])}" for s in shifts
              if s.get("people_trace")]  # fmt: skip
    if traces:
        lines += _part("People traces (`dume bench people-ids --run DIR`):", traces)
    with (out / "report.md").open("a") as f:
        f.write("\n".join(lines) + "\n")
    (out / "shift.json").write_text(json.dumps(json_safe(list(shifts)), indent=2) + "\n")
