"""`dume demo`'s and `dume eval`'s pure parts: choosing the request from the map, judging
a run against the sim's truth, and the report written from synthetic results."""

from __future__ import annotations

import json
import math
import os
import random
from pathlib import Path

import pytest

from bench.eval.judge import (
    MissionRecord,
    WorldResult,
    evaluate,
    judge,
    stage_reached,
    stage_times,
    stages_passed,
    transitions,
    truth_object,
    truth_person,
)
from bench.eval.pictures import reasons_table, wilson, world_picture
from bench.eval.report import summarize, write_report
from bench.eval.targets import TargetError, demo_pair, seeded_pair
from common.config import REPO_ROOT
from common.messages.mission import STAGES, MissionRequest, MissionState, MissionStatus
from common.messages.semantic_map import MapEntity
from common.messages.sim import HandoverTaken, ObjectDropped, RobotContact, WorldEvent
from common.messages.world import WorldDescription
from services.sim.world import generate_world

S = 1_000_000_000


@pytest.fixture(scope="module")
def hall() -> WorldDescription:
    return generate_world(0, "hall")


def entity(
    id_: str, xy: tuple[float, float], *, missing: bool = False, kind: str = ""
) -> MapEntity:
    cls = id_.rsplit("_", 1)[0]
    return MapEntity(
        id=id_,
        class_name=cls,
        kind="person" if (kind or cls) == "person" else "artifact",
        position_in_world=(xy[0], xy[1], 0.8),
        uncertainty_m=0.05,
        last_seen_ns=0,
        source="seed-from-world",
        missing_since_ns=3 * S if missing else None,
    )


def mapped(world: WorldDescription, noise_m: float = 0.05) -> tuple[list[MapEntity], ...]:
    """The world as the `seed-from-world` map sees it: truth ids, noisy positions."""
    rng = random.Random(1)

    def jitter(x: float, y: float) -> tuple[float, float]:
        return x + rng.uniform(-noise_m, noise_m), y + rng.uniform(-noise_m, noise_m)

    arts = [entity(a.id, jitter(a.position[0], a.position[1])) for a in world.artifacts]
    people = [entity(p.id, jitter(*p.position)) for p in world.people]
    return arts, people


# -- choosing the request ---------------------------------------------------------------


def test_the_demo_asks_for_the_bottle_and_person_farthest_apart(hall: WorldDescription) -> None:
    arts, people = mapped(hall)
    pair = demo_pair(arts, people)
    assert pair.object.startswith("bottle_") and pair.person.startswith("person_")
    bottles = [a for a in arts if a.class_name == "bottle"]
    farthest = max(
        math.dist(b.position_in_world[:2], p.position_in_world[:2]) for b in bottles for p in people
    )
    assert pair.distance_m == pytest.approx(farthest)


def test_the_demo_honours_a_chosen_object_or_person_and_picks_the_other_far_away(
    hall: WorldDescription,
) -> None:
    arts, people = mapped(hall)
    by_object = demo_pair(arts, people, object_="can_1")
    assert by_object.object == "can_1"
    can = next(a for a in arts if a.id == "can_1")
    assert by_object.distance_m == pytest.approx(
        max(math.dist(can.position_in_world[:2], p.position_in_world[:2]) for p in people)
    )
    assert demo_pair(arts, people, person="person_2").person == "person_2"
    assert demo_pair(arts, people, "bottle_1", "person_3")[:2] == ("bottle_1", "person_3")
    by_class = demo_pair(arts, people, object_="can")
    assert by_class.object == "can" and math.isnan(by_class.distance_m)


def test_the_demo_refuses_targets_the_map_does_not_hold(hall: WorldDescription) -> None:
    arts, people = mapped(hall)
    with pytest.raises(TargetError, match="bottle_99"):
        demo_pair(arts, people, object_="bottle_99")
    with pytest.raises(TargetError, match="person_9"):
        demo_pair(arts, people, person="person_9")
    with pytest.raises(TargetError, match="no person"):
        demo_pair(arts, [])


def test_the_eval_choice_is_seeded_and_picks_mapped_present_entities(
    hall: WorldDescription,
) -> None:
    arts, people = mapped(hall)
    arts[0] = entity(arts[0].id, (0.0, 0.0), missing=True)
    pairs = [seeded_pair(arts, people, seed) for seed in range(40)]
    assert pairs[:10] == [seeded_pair(list(reversed(arts)), people, s) for s in range(10)]
    present = {a.id for a in arts[1:]}
    assert all(p.object in present for p in pairs)
    assert all(p.person in {q.id for q in people} for p in pairs)
    assert len({p.object for p in pairs}) > 3  # it does vary with the seed
    with pytest.raises(TargetError):
        seeded_pair([], people, 0)


# -- judging against truth ----------------------------------------------------------------


def test_a_map_position_stands_for_the_nearest_true_entity(hall: WorldDescription) -> None:
    arts, people = mapped(hall, noise_m=0.1)
    for a in arts:
        match = truth_object(hall, (a.position_in_world[0], a.position_in_world[1]))
        assert match is not None and match.id == a.id and match.distance_m < 0.15
    for p in people:
        match = truth_person(hall, (p.position_in_world[0], p.position_in_world[1]))
        assert match is not None and match.id == p.id
    # A patrol's own ids: the position decides, not the name.
    bottle = next(a for a in hall.artifacts if a.id == "bottle_2")
    match = truth_object(hall, (bottle.position[0] + 0.03, bottle.position[1]))
    assert match is not None and match.id == "bottle_2"


def test_success_is_the_requested_object_in_the_requested_persons_hand() -> None:
    events: list[WorldEvent] = [
        RobotContact(
            stamp_ns=1 * S, body="trunk", other="table_1", position_in_world=(0, 0, 0), force=3.0
        ),
        HandoverTaken(stamp_ns=40 * S, person_id="person_2", object_id="bottle_1"),
    ]
    assert judge("bottle_1", "person_2", events).success
    wrong_person = judge("bottle_1", "person_3", events)
    assert not wrong_person.success and "person_2 took bottle_1" in wrong_person.reason
    wrong_object = judge("can_1", "person_2", events)
    assert not wrong_object.success
    dropped = judge(
        "bottle_1",
        "person_2",
        [ObjectDropped(stamp_ns=5 * S, object_id="bottle_1", position_in_world=(1, 1, 0))],
    )
    assert not dropped.success and "bottle_1 dropped at 5.0 s by (1.00, 1.00)" in dropped.reason
    assert "no handover" in judge("bottle_1", "person_2", []).reason


def status(
    t_s: float, state: MissionState, behaviour: str = "", rid: str = "r1", **kw: str
) -> MissionStatus:
    return MissionStatus(
        stamp_ns=round(t_s * S), request_id=rid, state=state, behaviour=behaviour, **kw
    )


def test_stage_times_and_stages_come_from_the_status_changes() -> None:
    stream = [
        status(0.0, "accepted"),
        status(0.1, "running", "navigate_to_object"),
        status(5.0, "running", "navigate_to_object"),  # repeated: not a change
        status(0.0, "running", "bring_to_user", rid="other"),  # another request: ignored
        status(20.0, "running", "approach_object"),
        status(26.0, "running", "pose_estimation"),
        status(27.0, "running", "pick_object"),
        status(40.0, "running", "navigate_to_object"),  # recovery: back again
        status(45.0, "running", "pick_object"),
        status(
            50.0, "failed", "pick_object", reason="grasp_failed", detail="the jaws closed on air"
        ),
    ]
    changes = transitions(stream, "r1")
    assert [c.stamp_ns for c in changes] == [round(t * S) for t in (0, 0.1, 20, 26, 27, 40, 45, 50)]
    times = stage_times(changes)
    assert times["navigate_to_object"] == pytest.approx(19.9 + 5.0)
    assert times["pick_object"] == pytest.approx(13.0 + 5.0)
    assert times["approach_object"] == pytest.approx(6.0)
    assert stages_passed(changes) == list(STAGES[:3])
    assert stage_reached(changes) == "pick_object"
    # Without a final state the last stage runs until watching stopped.
    assert stage_times(changes[:3], end_ns=30 * S)["approach_object"] == pytest.approx(10.0)
    done = [
        *changes[:5],
        status(60, "running", "bring_to_user"),
        status(80, "running", "release_object"),
        status(90, "succeeded", "release_object"),
    ]
    assert stages_passed(done) == list(STAGES)


def test_a_record_is_judged_from_truth_beside_the_missions_word(hall: WorldDescription) -> None:
    req = MissionRequest(request_id="r1", object="bottle_1", person="person_2")
    record = MissionRecord(request=req, start_ns=2 * S, end_ns=62 * S, wall_s=120.0)
    record.changes = [
        status(2, "accepted"),
        status(3, "running", "navigate_to_object"),
        status(62, "succeeded", "release_object"),
    ]
    record.events = [
        RobotContact(
            stamp_ns=10 * S,
            body="FL_thigh",
            other="table_1",
            position_in_world=(0, 0, 0),
            force=5.0,
        ),
        RobotContact(
            stamp_ns=11 * S,
            body="gripperMover",
            other="person_2",
            position_in_world=(0, 0, 0),
            force=1.0,
        ),
    ]
    base = WorldResult(
        world="hall",
        world_seed=0,
        scenario="standing",
        object="bottle_1",
        person="person_2",
        truth_object="bottle_1",
        truth_person="person_2",
    )
    r = evaluate(base, record, hall)
    assert r.outcome == "failed" and r.mission_state == "succeeded" and not r.agree
    assert r.contacts_static == 1 and r.drops == 0
    assert r.sim_time_s == pytest.approx(60.0) and r.rtf == pytest.approx(0.5)
    record.events.append(HandoverTaken(stamp_ns=60 * S, person_id="person_2", object_id="bottle_1"))
    r = evaluate(base, record, hall)
    assert r.succeeded and r.agree and r.failure == ""


# -- the report ----------------------------------------------------------------------------


def synthetic_results() -> list[WorldResult]:
    def world(seed: int, passed: int, ok: bool, **kw: object) -> WorldResult:
        return WorldResult(
            world="hall",
            world_seed=seed,
            scenario="standing",
            object="bottle_1",
            person="person_1",
            outcome="succeeded" if ok else "failed",
            mission_state="succeeded" if ok else "failed",
            agree=True,
            stages_passed=list(STAGES[:passed]),
            stage_reached=STAGES[min(passed, 5)],
            stage_times_s={s: 2.0 + i for i, s in enumerate(STAGES[: passed + 1])},
            sim_time_s=float(30 + seed),
            wall_time_s=float(60 + 2 * seed),
            **kw,  # type: ignore[arg-type]
        )

    loc = {"samples": 800, "position_p95_m": 0.031, "position_max_m": 0.052,
           "heading_p95_deg": 0.4, "lost": 0}  # fmt: skip
    placed = {"samples": 40, "map_error_p95_mm": 21.0, "base_error_p95_mm": 9.5,
              "excess_p95_mm": -2.1}  # fmt: skip
    return [
        world(0, 6, True, localization=loc, placement=placed),
        world(1, 6, True, localization=loc | {"position_p95_m": 0.044, "lost": 2}),
        world(
            2,
            3,
            False,
            mission_reason="grasp_failed",
            truth_reason="bottle_1 never reached person_1's hand",
            picture="worlds/seed-2.png",
            logs="var/run/run-2",
        ),
        world(3, 0, False, error="the stack did not come up: sim"),
        world(4, 6, True, contacts_static=2, drops=1),
    ]


def test_the_summary_counts_stages_successes_and_times() -> None:
    summary = summarize(synthetic_results())
    assert summary["worlds"] == 5 and summary["succeeded"] == 3
    assert summary["success_rate"] == pytest.approx(0.6)
    assert summary["stages_through"] == {
        "navigate_to_object": 4,
        "approach_object": 4,
        "pose_estimation": 4,
        "pick_object": 3,
        "bring_to_user": 3,
        "release_object": 3,
    }
    assert summary["errors"] == 1
    assert summary["sim_time_s"]["mean"] == pytest.approx((30 + 31 + 32 + 34) / 4)
    assert summary["sim_time_s_succeeded"]["median"] == pytest.approx(31.0)
    assert summary["rtf"] == pytest.approx(127 / (60 + 62 + 64 + 68), abs=1e-3)
    assert summary["contacts_static"] == 2 and summary["drops"] == 1


def test_the_report_and_plots_are_written_with_the_right_numbers(tmp_path: Path) -> None:
    results = synthetic_results()
    settings = {
        "segmenter": "network",
        "locomotion": "dynamic",
        "map start": "seed-from-world",
        "scenario": "standing people",
    }
    summary = write_report(tmp_path, settings, results)
    report = (tmp_path / "report.md").read_text()
    assert "segmenter: network" in report and "locomotion: dynamic" in report
    assert "**Success: 3/5 (60 %; 95 % interval 23-88 %, Wilson)**" in report
    assert "- commit: " in report and "cores, Python 3." in report
    assert "| grasp_failed | pick_object | 1 |" in report
    assert "| error | navigate_to_object | 1 |" in report
    logs = os.path.relpath(REPO_ROOT / "var/run/run-2", tmp_path)
    assert f"| [top-down](worlds/seed-2.png) | [run-2]({logs}) |" in report
    assert "  ![seed 2](worlds/seed-2.png)" in report
    assert "| navigate_to_object | 4 | 80 % |" in report
    assert "| pick_object | 3 | 60 % |" in report
    assert "world seed 2 (bottle_1 → person_1)" in report and "grasp_failed" in report
    assert "world seed 3" in report and "the stack did not come up" in report
    assert "position p95 ≤ 4.4 cm in every world (worst: seed 1)" in report
    assert "heading p95 ≤ 0.40°; 2 ticks lost" in report
    assert "| 0 | - | - | 3.1 | 5.2 | 0.4 | 40 | 21 | 9.5 | -2.1 |" in report
    assert "| 3 | - | - | - | - | - | - | - | - | - |" in report  # nothing measured
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["summary"] == json.loads(json.dumps(summary))
    assert [w["world_seed"] for w in doc["worlds"]] == [0, 1, 2, 3, 4]
    assert doc["worlds"][0]["truth_match_m"] == [None, None]  # NaN is not JSON
    for png in ("stage_times.png", "outcomes.png", "reasons.png"):
        data = (tmp_path / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


# -- the command lines' settings ------------------------------------------------------------


@pytest.fixture
def no_saved_maps(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """This machine's saved maps: an empty folder (the maps dume ships stay)."""
    from deploy import maps

    monkeypatch.setattr(maps, "SAVED_MAPS", tmp_path / "maps")
    return tmp_path / "maps"


def test_the_demo_and_eval_stacks_settings_are_valid_and_say_what_they_run(
    no_saved_maps: Path,
) -> None:
    from bench.eval.evaluate import world_overrides
    from common.config import load_config
    from deploy.cli import build_parser
    from deploy.demo import demo_overrides
    from deploy.maps import NoSavedMap

    args = build_parser().parse_args(
        ["eval", "--worlds", "2", "--world", "small", "--walking-people", "--map", "truth"]
    )
    cfg = load_config(world_overrides(args, 7, "eval-x-7"))
    assert (cfg.sim.world, cfg.sim.world_seed, cfg.sim.walking_people) == ("small", 7, True)
    assert cfg.sim.locomotion == "dynamic" and cfg.perception.segmenter == "network"
    assert cfg.semantic_map.start == "seed-from-world" and cfg.semantic_map.reset
    assert cfg.semantic_map.name == "eval-x-7" and cfg.semantic_map.seed_noise_seed == 7
    assert not cfg.recording.enabled and args.timeout == 300.0

    demo = build_parser().parse_args(["demo", "--world-seed", "3", "--map", "truth"])
    cfg = load_config(demo_overrides(demo, "demo-x"))
    assert (cfg.sim.world, cfg.sim.world_seed) == ("hall", 3)
    assert cfg.semantic_map.start == "seed-from-world" and cfg.recording.enabled
    assert cfg.semantic_map.floor_plan == "world"
    with pytest.raises(NoSavedMap, match="hall seed 3"):  # no saved map of it
        demo_overrides(
            build_parser().parse_args(["demo", "--world-seed", "3", "--map", "saved"]), "demo-x"
        )
    default = build_parser().parse_args(["demo", "--world-seed", "3"])
    assert default.map == "saved", "the robot's own map by default; truth only when asked"
    with pytest.raises(NoSavedMap, match="hall seed 3"):
        demo_overrides(default, "demo-x")
    assert build_parser().parse_args(["eval"]).map == "saved"
    prior = no_saved_maps.parent / "map.json"
    prior.write_text("{}")
    demo = build_parser().parse_args(["demo", "--map", str(prior)])
    cfg = load_config(demo_overrides(demo, "demo-x"))
    assert cfg.semantic_map.start == "prior" and cfg.semantic_map.prior_file == str(prior)
    assert cfg.semantic_map.floor_plan == "none"  # the file's grid is the static layer


def test_a_saved_map_is_found_by_its_site_and_an_unmapped_world_is_explored_and_saved(
    no_saved_maps: Path,
) -> None:
    from bench.eval.evaluate import map_source, world_overrides
    from common.config import load_config
    from deploy.cli import build_parser, map_start
    from deploy.demo import demo_overrides

    args = build_parser().parse_args(["eval", "--world", "small", "--seed", "41", "--map", "saved"])
    cfg = load_config(world_overrides(args, 41, "eval-x-41"))
    assert map_source("saved", "small", 41) == ("explore", no_saved_maps / "small-seed-41.json")
    assert cfg.semantic_map.start == "empty" and cfg.semantic_map.floor_plan == "none"
    assert cfg.mission.explore_semantic_pass and cfg.mission.explore_bounds
    assert map_start(None, "small", 41) == {"semantic_map.floor_plan": "none"}

    no_saved_maps.mkdir()
    saved = no_saved_maps / "small-seed-41.json"
    saved.write_text("{}")
    assert map_source("saved", "small", 41) == ("file", saved)
    cfg = load_config(world_overrides(args, 41, "eval-x-41"))
    assert (cfg.semantic_map.start, cfg.semantic_map.prior_file) == ("prior", str(saved))
    assert cfg.semantic_map.floor_plan == "none" and not cfg.mission.explore_bounds
    demo = build_parser().parse_args(
        ["demo", "--world", "small", "--world-seed", "41", "--map", "saved"]
    )
    assert load_config(demo_overrides(demo, "demo-x")).semantic_map.prior_file == str(saved)
    up = map_start(None, "small", 41)  # the site's own database starts from it
    assert (up["semantic_map.start"], up["semantic_map.name"]) == ("prior", "small-seed-41")
    # a folder of the user's: only that folder
    other = no_saved_maps.parent / "other"
    assert map_source(str(other), "small", 41) == ("explore", other / "small-seed-41.json")
    assert map_source("explored", "small", 41) == ("explore", None)


def test_a_world_is_drawn_from_above_with_the_run_on_it(
    hall: WorldDescription, tmp_path: Path
) -> None:
    req = MissionRequest(request_id="r1", object="bottle_1", person="person_2")
    record = MissionRecord(request=req, start_ns=0, end_ns=30 * S, wall_s=30.0)
    record.changes = [status(1, "running", "navigate_to_object"),
                      status(20, "failed", "pick_object")]  # fmt: skip
    start = hall.robot_start
    record.trajectory = [(k * 0.1 * S, start.x + 0.05 * k, start.y, 0.5, 0, 0, 0, 1)
                         for k in range(300)]  # fmt: skip
    result = WorldResult(world="hall", world_seed=0, scenario="standing", object="bottle_1",
                         person="person_2", truth_object="bottle_1", truth_person="person_2",
                         mission_reason="grasp_failed", stage_reached="pick_object")  # fmt: skip
    out = tmp_path / "worlds" / "seed-0.png"
    world_picture(hall, record, result, out)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_the_wilson_interval_and_the_reasons_table() -> None:
    assert wilson(19, 20) == pytest.approx((0.764, 0.991), abs=1e-3)
    assert wilson(0, 5)[0] == 0.0 and wilson(5, 5)[1] == 1.0
    assert reasons_table(synthetic_results()[:2]) == ["- none"]


def test_a_report_without_failures_draws_its_reasons_too(tmp_path: Path) -> None:
    write_report(tmp_path, {}, synthetic_results()[:2])
    assert (tmp_path / "reasons.png").read_bytes()[:4] == b"\x89PNG"


def test_dume_up_looks_for_the_sites_database_where_set_puts_the_map(tmp_path: Path) -> None:
    """`dume up --set semantic_map.dir=D`: the site's map is resumed from D when D has
    it, and started from the saved map when D has none, whatever var/map/ holds."""
    from deploy.cli import map_start

    where = {"semantic_map.dir": str(tmp_path)}
    fresh = map_start(None, "small", 0, where)  # D has no database: the shipped saved map
    assert (fresh["semantic_map.start"], fresh["semantic_map.name"]) == ("prior", "small-seed-0")
    (tmp_path / "small-seed-0.sqlite").write_bytes(b"")
    assert map_start(None, "small", 0, where) == {"semantic_map.floor_plan": "none"}
