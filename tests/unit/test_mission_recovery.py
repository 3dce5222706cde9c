"""The tree's recoveries, scripted: re-pick after a lost grasp, the next instance of a class."""

from __future__ import annotations

import msgspec

from common.messages.mission import MissionRequest
from common.messages.navigation import ArtifactStandoff
from common.messages.wbc import Grasp
from services.mission.targets import object_candidates
from services.mission.tree import MissionTree
from tests.unit.mission_fakes import FakeRobot, context, entity, small_world
from tests.unit.test_mission_tree import REQUEST, mission, run


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
    assert standoffs(robot) == ["bottle_1"]  # it fell by the robot: no walk back to its table
    decisions = tree.ctx.decisions  # type: ignore[attr-defined]
    assert any("regrasp: grasp_lost: try 1 of 2" in d for d in decisions)
    assert any("bottle_1 fell at (" in d for d in decisions), decisions
    # The wrist camera looked for it at its mapped place; dropped, where it fell.
    places = list(dict.fromkeys(robot.looked_near))
    fell = next(d for d in decisions if "bottle_1 fell at (" in d)
    x, y = (float(v) for v in fell.split("fell at (")[1].split(")")[0].split(", "))
    assert len(places) == 2 and places[0] == (3.0, 0.0), places
    assert places[1] is not None and abs(places[1][0] - x) < 0.01 and abs(places[1][1] - y) < 0.01


def test_an_object_dropped_where_the_arm_cannot_reach_fails_object_dropped_saying_where() -> None:
    """A knock while carrying drops the bottle on the floor: it is seen there, but no
    grasp reaches the floor. The request ends at once, saying where it lies (a person
    picks it up), not after a search of its old table for something that is not there."""
    robot = small_world(drops=1)
    tree = MissionTree(context(robot, None, grasp_plans=1))
    tree.tick()
    robot.advance()
    tree.start(REQUEST)
    outcome = run(tree, robot)
    assert (outcome.state, outcome.reason) == ("failed", "object_dropped"), outcome
    assert "bottle_1 fell at (" in outcome.detail and "cannot pick it up" in outcome.detail
    assert grasps(robot) == 1 and standoffs(robot) == ["bottle_1"]


def test_an_object_dropped_out_of_sight_fails_object_dropped() -> None:
    robot = small_world(drops=1, drop_hides=True)
    outcome = run(mission(robot), robot)
    assert (outcome.state, outcome.reason) == ("failed", "object_dropped"), outcome
    assert "not found where it fell" in outcome.detail
    assert standoffs(robot) == ["bottle_1"]


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


def test_a_class_request_tries_entries_of_a_few_far_views_after_the_firm_ones() -> None:
    """Hall seed 1's shift: a "box_6" of 6 head-camera detections on a pallet's edge was
    fetched first, a 51-s walk, with a box the map had seen often 5 m further."""
    flimsy = msgspec.structs.replace(entity("box_6", 1.0, 0.0), source="perception",
                                     observations=6, nearest_view_m=4.5)  # fmt: skip
    seen = msgspec.structs.replace(entity("box_2", 6.0, 0.0), source="perception",
                                   observations=40, nearest_view_m=1.2)  # fmt: skip
    robot = small_world(artifacts={"box_6": flimsy, "box_2": seen}, visible={"box_2"})
    request = MissionRequest(request_id="r", object="box", person="person_1")
    outcome = run(mission(robot, request), robot)
    assert outcome.state == "succeeded", outcome
    assert standoffs(robot) == ["box_2"]
    assert [e.id for e in object_candidates(robot, "box")] == ["box_2", "box_6"]


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


def test_where_a_dropped_object_is_looked_for() -> None:
    """It fell below the carry posture's TCP, half a metre ahead of the base; the robot
    looks at it from where its wrist camera sees the floor, facing it."""
    import math

    from common.robot import floor_view_m, posture_tcp
    from services.mission.behaviours.motion import look_where_it_fell
    from services.mission.targets import dropped_at

    assert dropped_at(None, 0.0) is None and dropped_at((1.0, 2.0), None) is None
    ahead = posture_tcp("stow")[0]
    x, y = dropped_at((1.0, 2.0), math.pi / 2) or (0.0, 0.0)
    assert math.isclose(y, 2.0 + ahead) and abs(x - 1.0) < 0.05
    assert 1.2 < floor_view_m() < 1.8
    goal = look_where_it_fell((1.0, 2.5), (1.0, 2.0), math.pi / 2)
    assert math.isclose(goal.yaw, math.pi / 2)
    assert math.isclose(goal.y, 2.5 - floor_view_m()) and math.isclose(goal.x, 1.0, abs_tol=1e-9)
    on_the_spot = look_where_it_fell((1.0, 2.0), (1.0, 2.0), 0.0)  # its heading, then
    assert math.isclose(on_the_spot.x, 1.0 - floor_view_m()) and on_the_spot.yaw == 0.0
