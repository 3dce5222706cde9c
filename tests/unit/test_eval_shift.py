"""`dume eval --shift`'s pure parts: the requests, the truth of the moment, the separation."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from bench.eval import judge
from bench.eval.judge import MissionRecord, WorldResult
from bench.eval.shift import (
    CLASS_EVERY,
    Follow,
    Knock,
    Truth,
    class_verdict,
    firm_people,
    leave_trolley,
    present_artifacts,
    put_away,
    real_people,
    shift_request,
    whom,
)
from bench.separation import SeparationWatch
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.semantic_map import MapEntity
from common.messages.sim import (
    Clock,
    HandoverTaken,
    PeopleTruth,
    PersonTruth,
    StateTruth,
)
from services.navigation.separation import SeparationParams, protective_distance
from services.sim.world import generate_world

S = 1_000_000_000


def _entity(eid: str, x: float, y: float, kind: str = "artifact") -> MapEntity:
    return MapEntity(id=eid, class_name=eid.split("_")[0], kind=kind,  # type: ignore[arg-type]
                     position_in_world=(x, y, 0.8), uncertainty_m=0.05, last_seen_ns=0,
                     source="perception")  # fmt: skip


def test_only_artifacts_that_still_stand_where_the_map_has_them_are_asked_for() -> None:
    where = {"bottle_1": (1.0, 0.0, 0.8), "bottle_2": (5.0, 0.0, 0.8), "can_1": (3.0, 0.0, 0.8)}
    mapped = [
        _entity("bottle_7", 1.1, 0.0),  # bottle_1, 10 cm off
        _entity("bottle_8", 4.0, 0.0),  # bottle_2 moved away from here: 1 m
        _entity("box_1", 3.0, 0.0),  # the can is no box
        _entity("can_4", 3.0, 0.1),  # can_1, but handed over already
    ]
    present = present_artifacts(mapped, where, gone={"can_1"})
    assert [(e.id, t) for e, t in present] == [("bottle_7", "bottle_1")]


def test_a_shift_asks_by_class_every_third_request_and_for_someone_else_each_time() -> None:
    present = [(_entity("bottle_1", 1.0, 0.0), "bottle_1"), (_entity("can_1", 3.0, 0.0), "can_1")]
    people = [_entity("person_1", 0.0, 0.0, "person"), _entity("person_2", 5.0, 0.0, "person")]
    last = ""
    for k in range(6):
        pair, asked = shift_request(present, people, 7, k, last)
        assert pair.person != last
        if k % CLASS_EVERY == CLASS_EVERY - 1:
            assert pair.object in ("bottle", "can") and asked == ""
        else:
            assert pair.object == asked and asked in ("bottle_1", "can_1")
        last = pair.person
    assert shift_request(present, people, 7, 4, "x") == shift_request(present, people, 7, 4, "x")


def test_a_shift_asks_for_people_the_map_keeps() -> None:
    """Hall seed 3's shift asked for person_7, made from two detections, which the map
    deleted as a false entry while the robot fetched the bottle (`unknown_person`)."""
    seeded = msgspec.structs.replace(_entity("person_1", 0.0, 0.0, "person"),
                                     source="seed-from-world")  # fmt: skip
    made = msgspec.structs.replace(_entity("person_7", 1.0, 0.0, "person"), observations=2)
    kept = msgspec.structs.replace(made, id="person_9", observations=10)
    assert [p.id for p in firm_people([seeded, made, kept], 10)] == ["person_1", "person_9"]


def test_the_truth_of_the_moment_has_the_moved_artifacts_and_walking_people() -> None:
    truth = Truth(generate_world(0, "small"))
    truth.where["bottle_1"] = (-2.0, 1.0, 0.0)
    moving = PersonTruth(id="person_1", position=(1.5, -1.0), yaw=0.0, velocity=(0.5, 0.0))
    walked = PeopleTruth(stamp_ns=0, people=[moving])
    now = truth.now(walked)
    assert now.artifacts[0].position == (-2.0, 1.0, 0.0)
    assert now.people[0].position == (1.5, -1.0)
    truth.gone.add("bottle_1")
    assert truth.now(None).artifacts == ()


def _base(x: float, vx: float) -> StateTruth:
    return StateTruth(stamp_ns=0, base_position_in_world=(x, 0.0, 0.5),
                      base_orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
                      base_linear_velocity_in_world=(vx, 0.0, 0.0),
                      base_angular_velocity_in_base=(0.0, 0.0, 0.0))  # fmt: skip


def test_moving_towards_a_person_inside_the_protective_separation_is_a_violation() -> None:
    """A person standing at x = 2: at 0.2 m/s from 1.48 m the robot keeps S_p (0.52 m);
    at 0.6 m/s from 0.68 m it does not (S_p 0.94 m); at rest or moving away, never."""
    sep = SeparationParams(speed_margin_mps=0.0)
    watch = SeparationWatch(sep)
    standing = [PersonTruth(id="person_1", position=(2.0, 0.0), yaw=0.0, velocity=(0.0, 0.0))]
    person = PeopleTruth(stamp_ns=0, people=standing)
    watch.add(_base(0.0, 0.2), person)
    assert watch.violations == 0
    assert watch.least_margin_m == pytest.approx(
        1.478 - protective_distance(0.2, 0.0, sep), abs=1e-3
    )
    watch.add(_base(0.8, 0.0), person)  # at rest
    watch.add(_base(0.8, -0.5), person)  # moving away
    assert watch.violations == 0
    watch.add(_base(0.8, 0.6), person)
    f = watch.figures()
    assert f["violations"] == 1 and f["least_margin_m"] < 0 and f["samples"] == 4
    (v,) = f["violations_kept"]
    assert (v["person"], v["d_m"], v["v_robot_mps"]) == ("person_1", 0.678, 0.6)
    assert (v["robot_xy_yaw"], v["person_xy"], v["person_velocity"]) == (
        [0.8, 0.0, 0.0],
        [2.0, 0.0],
        [0.0, 0.0],
    )  # where: the report's reader finds the moment
    assert f["closest_m"] == pytest.approx(0.678, abs=1e-3) and f["closest_person"] == "person_1"


def test_a_class_request_succeeds_when_the_person_took_any_artifact_of_that_class() -> None:
    record = MissionRecord(
        request=MissionRequest(request_id="r", object="can", person="person_2"), start_ns=0,
        events=[HandoverTaken(stamp_ns=5, person_id="person_1", object_id="can_2")],
    )  # fmt: skip
    result = WorldResult(world="hall", world_seed=0, scenario="", truth_person="person_1")
    class_verdict(result, record, "can")
    assert result.succeeded and result.truth_object == "can_2"
    other = WorldResult(world="hall", world_seed=0, scenario="", truth_person="person_1")
    class_verdict(other, record, "bottle")
    assert not other.succeeded
    assert other.truth_reason == "person_1 took no bottle (person_1 took can_2)"


class _Fifo:
    def __init__(self) -> None:
        self.items: list[object] = []

    def drain(self) -> Iterator[object]:  # a generator, as `common.bus.Fifo.drain`
        out, self.items = self.items, []
        yield from out


def test_people_samples_are_judged_with_the_base_of_their_own_stamp() -> None:
    """The base walks towards a standing person; each people sample (every 100 ms) is
    paired with the base at its stamp, not the newest: one whose base has not come yet
    waits for the next drain."""
    people, base = _Fifo(), _Fifo()
    watch = SeparationWatch(SeparationParams(speed_margin_mps=0.0))
    follow = Follow(people, base, watch)  # type: ignore[arg-type]
    standing = [PersonTruth(id="person_1", position=(2.0, 0.0), yaw=0.0, velocity=(0.0, 0.0))]
    for k in range(10):  # base every 20 ms at 0.5 m/s from x = 0
        t = k * 20_000_000
        base.items.append(msgspec.structs.replace(_base(0.5 * t / 1e9, 0.5), stamp_ns=t))
    people.items += [
        PeopleTruth(stamp_ns=t, people=standing) for t in (0, 100_000_000, 200_000_000)
    ]
    follow.drain()
    assert watch.samples == 2  # 0 and 100 ms; 200 ms's base has not come yet
    base.items.append(msgspec.structs.replace(_base(0.1, 0.5), stamp_ns=200_000_000))
    follow.drain()
    assert watch.samples == 3
    assert watch.closest_m == pytest.approx(2.0 - 0.1 - watch.fp.front, abs=1e-6)


def test_the_person_asked_for_is_who_stood_at_the_maps_estimate_when_it_last_saw_them() -> None:
    """Two people: person_1 stood at (1, 1) when the map last saw "person_7" there (t = 2
    s) and has walked 4 m on since; person_2 now stands next to that stale estimate. The
    request is for person_1, not for whoever is nearest the estimate at the request."""
    truth = Truth(generate_world(0, "hall"))  # five people: the others stay where they stand
    people, base = _Fifo(), _Fifo()
    follow = Follow(people, base, SeparationWatch(SeparationParams()))  # type: ignore[arg-type]
    for k in range(41):  # 10 s at 4 Hz: person_1 walks along x from (1, 1); person_2 comes
        t = k * 250_000_000
        walker = PersonTruth(id="person_1", position=(1.0 + 0.4 * t / S, 1.0), yaw=0.0,
                             velocity=(0.4, 0.0))  # fmt: skip
        comer = PersonTruth(id="person_2", position=(3.0 - 0.18 * t / S, 1.2), yaw=0.0,
                            velocity=(-0.18, 0.0))  # fmt: skip
        people.items.append(PeopleTruth(stamp_ns=t, people=[walker, comer]))
    follow.drain()
    assert follow.people_at(2 * S + 10) is not None
    mapped = msgspec.structs.replace(_entity("person_7", 1.8, 1.0, "person"), last_seen_ns=2 * S)
    result = WorldResult(world="small", world_seed=0, scenario="bystanders")
    result.truth_person, result.truth_match_m = "person_2", (0.0, 0.2)  # nearest at t = 10 s
    now = follow.people_at(10 * S)
    assert now is not None
    stale = judge.truth_person(truth.now(now), (1.8, 1.0))
    assert stale is not None and stale.id == "person_2"  # nearest the estimate at the request
    whom(result, "person_7", [mapped], follow, truth)
    assert result.truth_person == "person_1"
    assert result.truth_match_m[1] == pytest.approx(0.0, abs=1e-6)


def test_a_saved_maps_person_unseen_this_run_is_who_stood_there_as_the_run_began() -> None:
    """The hall's person_2 starts at (-6.79, 0.93) and has walked 5 m off by the request; a
    saved map's person the run never saw stands 0.2 m from that start: it is person_2,
    not whoever is nearest to it at the request. A mapped person 3 m from anybody at the
    start stands for nobody, and is not drawn."""
    truth = Truth(generate_world(0, "hall"))
    people, base = _Fifo(), _Fifo()
    follow = Follow(people, base, SeparationWatch(SeparationParams()))  # type: ignore[arg-type]
    start = {p.id: p.position for p in truth.world.people}
    moved = [PersonTruth(id=i, position=(x + (5.0 if i == "person_2" else 0.0), y), yaw=0.0,
                         velocity=(0.0, 0.0)) for i, (x, y) in start.items()]  # fmt: skip
    people.items.append(PeopleTruth(stamp_ns=60 * S, people=moved))
    follow.drain()
    prior = _entity("person_5", -6.63, 0.78, "person")  # never seen this run
    ghost = _entity("person_9", 0.0, 8.0, "person")
    result = WorldResult(world="hall", world_seed=0, scenario="bystanders")
    whom(result, "person_5", [prior], follow, truth)
    assert result.truth_person == "person_2"
    real, ghosts = real_people([prior, ghost], follow, truth)
    assert [p.id for p in real] == ["person_5"] and ghosts == ["person_9"]


class _Pub:
    def __init__(self) -> None:
        self.sent: list[Any] = []

    def put(self, msg: Any) -> None:
        self.sent.append(msg)


def test_a_slip_knocks_the_carried_object_once_three_seconds_into_the_carry() -> None:
    def status(t_s: float, behaviour: str) -> MissionStatus:
        return MissionStatus(stamp_ns=round(t_s * 1e9), request_id="r", state="running",
                             behaviour=behaviour)  # fmt: skip

    clock = Clock(stamp_ns=0, tick=0, mode="lockstep", rtf=1.0)
    pub, lines = _Pub(), []
    knock = Knock(pub, "bottle_2", True, lambda *a: lines.append(a))
    for t, b in ((1.0, "pick_object"), (10.0, "bring_to_user"), (11.0, "bring_to_user")):
        knock.on_progress(status(t, b), clock, True)
    assert [(m.target, m.stamp_ns) for m in pub.sent] == [("bottle_2", 13_000_000_000)]
    assert len(lines) == 3  # the stage lines still go out
    unarmed, by_class = Knock(_Pub(), "bottle_2", False, print), Knock(_Pub(), "", True, print)
    for k in (unarmed, by_class):
        k.on_progress(status(10.0, "bring_to_user"), clock, False)
        k.on_progress(status(10.0, "bring_to_user"), clock, True)
        assert not k.pusher.sent and not k.at_ns


def test_the_trolley_is_left_in_an_aisle_half_the_time_clear_of_everyone_and_recorded() -> None:
    hall = generate_world(0)
    start = hall.robot_start
    base = StateTruth(stamp_ns=0, base_position_in_world=(start.x, start.y, 0.5),
                      base_orientation_xyzw=(0.0, 0.0, math.sin(start.yaw / 2),
                                             math.cos(start.yaw / 2)),
                      base_linear_velocity_in_world=(0.0, 0.0, 0.0),
                      base_angular_velocity_in_base=(0.0, 0.0, 0.0))  # fmt: skip
    truth, pub, rng = Truth(hall), _Pub(), np.random.default_rng(3)
    for k in range(8):
        leave_trolley(truth, pub, rng, base, None, (k + 1) * S)
    assert 1 <= len(pub.sent) <= 7  # half the time, by its own draws
    assert len(truth.moves) == len(pub.sent)
    for m in pub.sent:
        assert m.movable_id == "trolley_1" and m.position is not None
        assert math.dist(m.position, (start.x, start.y)) >= 1.5
        assert all(math.dist(m.position, p.position[:2]) >= 1.5 for p in hall.people)
    small = Truth(generate_world(0, "small"))  # no movable: nothing left anywhere
    leave_trolley(small, pub2 := _Pub(), np.random.default_rng(0), base, None, S)
    assert not pub2.sent and not small.moves


def test_what_a_person_took_is_carried_away_before_the_next_request_freeing_their_hand() -> None:
    """Hall seed 3's shift: person_2 still held request 1's bottle when request 3's was
    held out to them, and the sim's hand, holding one thing, took nothing for 60 s."""
    truth, pub = Truth(generate_world(3)), _Pub()
    taken = [HandoverTaken(stamp_ns=71 * S, person_id="person_2", object_id="bottle_2")]
    put_away(truth, pub, taken, 80 * S)
    assert [(m.artifact_id, m.away, m.stamp_ns) for m in pub.sent] == [("bottle_2", True, 80 * S)]
    assert truth.moves == ["bottle_2 taken away by person_2 at 80.0 s"]
    put_away(truth, pub, [], 90 * S)  # nobody took anything: nothing carried off
    assert len(pub.sent) == 1


def test_the_map_accuracy_counts_artifacts_within_10_cm_and_entries_still_true() -> None:
    from bench.eval.shift_plots import map_accuracy

    def entity(eid: str, x: float, missing: bool = False) -> MapEntity:
        e = _entity(eid, x, 0.0)
        return msgspec.structs.replace(e, missing_since_ns=0) if missing else e

    where = {"bottle_1": (0.05, 0.0, 0.8), "can_1": (3.0, 0.0, 0.8)}
    # bottle right; can_1's entry stale (2 m off); a box entry for nothing there;
    # a missing entry not counted either way.
    arts = [entity("bottle_1", 0.0), entity("can_1", 1.0), entity("box_1", 5.0),
            entity("can_2", 3.0, missing=True)]  # fmt: skip
    within, current = map_accuracy(arts, where)
    assert within == 0.5 and current == pytest.approx(1 / 3)
    assert map_accuracy([], {}) == (1.0, 1.0)


def test_the_shift_plots_are_a_rerun_recording_of_separation_stages_and_accuracy(
    tmp_path: Path,
) -> None:
    from bench.eval.shift_plots import ShiftPlots

    plots = ShiftPlots(slow_zone_m=2.0)
    plots.changes = [
        MissionStatus(stamp_ns=0, request_id="r1", state="running", behaviour="navigate_to_object"),
        MissionStatus(stamp_ns=5 * S, request_id="r1", state="failed", reason="grasp_failed"),
    ]
    plots.accuracy = [(0.0, 1.0, 1.0), (6.0, 0.5, 0.8)]
    series = [(0.1 * k, 2.0 - 0.01 * k, 0.5, 0.3) for k in range(100)]
    path = tmp_path / "shift-seed-0.rrd"
    plots.write(path, series)
    assert path.stat().st_size > 1000
