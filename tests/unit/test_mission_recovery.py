"""The tree's recoveries, scripted: re-pick after a lost grasp, the next instance of a class."""

from __future__ import annotations

from common.messages.mission import MissionRequest
from common.messages.navigation import ArtifactStandoff
from common.messages.wbc import Grasp
from tests.unit.mission_fakes import FakeRobot, entity, small_world
from tests.unit.test_mission_tree import mission, run


def grasps(robot: FakeRobot) -> int:
    return sum(isinstance(g, Grasp) for _, g in robot.arm_goals)


def standoffs(robot: FakeRobot) -> list[str]:
    return [g.artifact_id for _, g in robot.nav_goals if isinstance(g, ArtifactStandoff)]


def test_a_grasp_lost_while_carrying_is_picked_again_and_the_mission_succeeds() -> None:
    robot = small_world(drops=1)
    tree = mission(robot)
    outcome = run(tree, robot)
    assert outcome.state == "succeeded", outcome
    assert grasps(robot) == 2
    assert standoffs(robot) == ["bottle_1", "bottle_1"]  # went back to the object
    decisions = tree.ctx.decisions  # type: ignore[attr-defined]
    assert any("regrasp: grasp_lost: try 1 of 2" in d for d in decisions)
    # The wrist camera looked for it at its mapped place; dropped on the way, anywhere.
    places = list(dict.fromkeys(robot.looked_near))
    assert places == [(3.0, 0.0), None], places


def test_a_grasp_that_closed_on_nothing_looks_for_the_object_at_its_place_again() -> None:
    robot = small_world(grasp_misses=1)
    run(mission(robot), robot)
    assert set(robot.looked_near) == {(3.0, 0.0)}


def test_a_grasp_lost_three_times_fails_once_the_budget_of_two_is_spent() -> None:
    robot = small_world(drops=3)
    outcome = run(mission(robot), robot)
    assert (outcome.state, outcome.reason) == ("failed", "grasp_lost")
    assert grasps(robot) == 3  # the first pick and two re-picks


def test_a_grasp_that_closes_on_nothing_is_tried_again_within_the_budget() -> None:
    robot = small_world(grasp_misses=2)
    outcome = run(mission(robot), robot)
    assert outcome.state == "succeeded"
    assert grasps(robot) == 3


def test_a_class_request_tries_the_next_instance_when_the_nearest_is_not_there() -> None:
    robot = small_world(
        artifacts={
            "bottle_1": entity("bottle_1", 1.0, 0.0),  # nearest, but not where the map says
            "bottle_2": entity("bottle_2", 4.0, 0.0),
            "bottle_3": entity("bottle_3", 8.0, 0.0),
        },
        visible={"bottle_2", "bottle_3"},
    )
    request = MissionRequest(request_id="r", object="bottle", person="person_1")
    outcome = run(mission(robot, request), robot)
    assert outcome.state == "succeeded", outcome
    assert standoffs(robot) == ["bottle_1", "bottle_2"]


def test_a_class_request_fails_object_not_found_after_every_candidate() -> None:
    robot = small_world(
        artifacts={
            "bottle_1": entity("bottle_1", 1.0, 0.0),
            "bottle_2": entity("bottle_2", 4.0, 0),
        },
        visible={"can_1"},
    )
    request = MissionRequest(request_id="r", object="bottle", person="person_1")
    outcome = run(mission(robot, request), robot)
    assert (outcome.state, outcome.reason) == ("failed", "object_not_found")
    assert standoffs(robot) == ["bottle_1", "bottle_2"]


def test_a_map_id_request_is_not_swapped_for_another_instance() -> None:
    robot = small_world(
        artifacts={
            "bottle_1": entity("bottle_1", 1.0, 0.0),
            "bottle_2": entity("bottle_2", 4.0, 0),
        },
        visible={"bottle_2"},
    )
    outcome = run(mission(robot), robot)
    assert (outcome.state, outcome.reason) == ("failed", "object_not_found")
    assert standoffs(robot) == ["bottle_1"]


def test_a_class_request_skips_instances_the_map_marks_missing() -> None:
    missing = entity("bottle_1", 1.0, 0.0)
    missing = type(missing)(**{**{f: getattr(missing, f) for f in missing.__struct_fields__},
                               "missing_since_ns": 5})  # fmt: skip
    robot = small_world(
        artifacts={"bottle_1": missing, "bottle_2": entity("bottle_2", 4.0, 0.0)},
        visible={"bottle_2"},
    )
    request = MissionRequest(request_id="r", object="bottle", person="person_1")
    assert run(mission(robot, request), robot).state == "succeeded"
    assert standoffs(robot) == ["bottle_2"]
