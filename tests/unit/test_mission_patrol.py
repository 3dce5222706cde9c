"""The mapping patrol on the mission's port, without Zenoh (`mission_fakes.FakeRobot`).

`PatrolRunner`: walk obeying navigation, the arm to `look` first (walking on when it does
not get there in `ARM_WAIT_S`), the viewpoints' pose goals in order with the look-around
turns, a refused viewpoint skipped, a stop that cancels the goal and stows the arm.
`PatrolDesk`: requests taken by the loop and answered, one job at a time with the fetch
(`busy` both ways), the route planned from the map's grid, the status every tick.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time

import numpy as np
import pytest
import rerun as rr

from common.bus import RequestError
from common.lifelines import Dependencies, Lifelines
from common.messages import encode, to_wire
from common.messages.mission import MissionRequest, MissionStatus, PatrolRequest, PatrolStatus
from common.messages.navigation import NavGoal, PoseGoal
from common.messages.semantic_map import OccupancyGrid
from common.messages.world import OCCUPIED, SupportSurface
from services.mission.coverage import Route
from services.mission.desk import Desk
from services.mission.goal_job import HELD_UP_S
from services.mission.inbox import Inbox, RequestInbox
from services.mission.mission_log import MissionLogger
from services.mission.node import DEPENDENCIES
from services.mission.patrol import ARM_WAIT_S, PatrolRunner, plan_patrol
from services.mission.patrol_desk import PatrolDesk
from services.mission.ports import Refused
from services.mission.requests import StatusBoard
from services.mission.tree import MissionTree
from tests.unit.mission_fakes import TICK_NS, FakeRobot, context, fast_settings, small_world

LOG = logging.getLogger("test.mission.patrol")
VIEWPOINTS = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]


def _route() -> Route:
    points = [(0.0, 0.0), *VIEWPOINTS]
    paths = [np.array([a, b]) for a, b in itertools.pairwise(points)]
    return Route([np.array(v) for v in VIEWPOINTS], paths)


def _run(robot: FakeRobot, runner: PatrolRunner, ticks: int) -> list[PatrolStatus]:
    """`ticks` mission ticks of the patrol; its status after each."""
    out = []
    for _ in range(ticks):
        runner.step()
        out.append(runner.status(robot.now_ns))
        robot.advance()
    return out


def _walks(robot: FakeRobot) -> list[tuple[float, float]]:
    """The places of the pose goals sent, once each (a walk and its turns share one)."""
    places: list[tuple[float, float]] = []
    for _id, goal in robot.nav_goals:
        assert isinstance(goal, PoseGoal)
        if not places or places[-1] != (goal.x, goal.y):
            places.append((goal.x, goal.y))
    return places


def test_the_route_is_walked_viewpoint_by_viewpoint_with_the_arm_in_look() -> None:
    robot = FakeRobot()
    runner = PatrolRunner(robot, fast_settings())
    runner.start(_route())
    statuses = _run(robot, runner, robot.arm_ticks)
    assert robot.arm_kinds() == ["look"] and robot.nav_goals == []  # the arm first
    assert robot.modes == [("walk", "navigation")]
    statuses += _run(robot, runner, 200)
    assert runner.state == "done" and runner.detail == ""
    assert robot.modes[-1] == ("stand", "navigation")
    assert robot.arm_kinds() == ["look", "stow"]
    assert len(robot.nav_goals) == 4 * len(VIEWPOINTS)  # a walk and three turns each
    assert _walks(robot) == VIEWPOINTS
    assert statuses[robot.arm_ticks].arm_look  # the map fuses the wrist camera from here
    assert statuses[-1].state == "done" and not statuses[-1].arm_look
    assert statuses[-1].waypoints == 3 and statuses[-1].travelled_m > 2.9
    assert not robot.active_nav_goals()


def test_a_route_that_faces_holds_at_each_viewpoint_before_it_walks_on_or_ends() -> None:
    # the semantic pass and the second look: the map needs its looks at each place
    robot = FakeRobot()
    runner = PatrolRunner(robot, fast_settings(patrol_dwell_s=0.5))  # 10 ticks
    route = _route()
    runner.start(Route(route.viewpoints, route.paths, facings=[0.0, 1.5, 3.0]))
    sent: list[int] = []  # the tick each goal went out
    done = None
    for k in range(200):
        runner.step()
        if len(robot.nav_goals) > len(sent):
            sent.append(k)
        if runner.state == "done" and done is None:
            done = k
        robot.advance()
    assert _walks(robot) == VIEWPOINTS and len(robot.nav_goals) == 3  # no turns
    assert done is not None
    # a goal takes nav_ticks; then the hold of 10 ticks: the next one (or the end) after
    gaps = [b - a for a, b in itertools.pairwise([*sent, done])]
    assert all(g >= robot.nav_ticks + 10 for g in gaps), gaps
    # a route without facings (the lattice's look-around) does not hold
    plain = FakeRobot()
    lattice = PatrolRunner(plain, fast_settings(patrol_dwell_s=0.5))
    lattice.start(_route())
    assert lattice.dwell_ns == 0


def test_a_walk_held_up_within_reach_of_its_viewpoint_has_arrived_there() -> None:
    """Hall seed 4's shift: the search's robot stood 6 cm from a viewpoint for 105 s, the
    last 35° of its turn refused (people crossing, a map cell at its flank); navigation
    never said it arrived. A viewpoint is a place to look from."""
    robot = FakeRobot(nav_ticks=10**6)  # navigation never says a goal arrived
    said: list[str] = []
    runner = PatrolRunner(robot, fast_settings(patrol_dwell_s=0.5), said.append)
    near, far = (0.3, 0.0), (3.0, 0.0)
    points = [(0.0, 0.0), near, far]
    paths = [np.array([a, b]) for a, b in itertools.pairwise(points)]
    runner.start(Route([np.array(near), np.array(far)], paths, facings=[0.0, 0.0]))
    held = round(HELD_UP_S * 1e9 / TICK_NS)
    _run(robot, runner, robot.arm_ticks + held - 20)
    assert len(robot.nav_goals) == 1 and not robot.nav_cancels  # still walking to it
    _run(robot, runner, 40 + 10)  # held up long enough, then the hold there (10 ticks)
    assert robot.nav_cancels == [robot.nav_goals[0][0]]
    assert _walks(robot) == [near, far]  # on to the next, which the robot is far from
    assert any("viewpoint 1: held up 15 s within 0.30 m of it: looking from here" in m
               for m in said), said  # fmt: skip
    _run(robot, runner, 2 * held)
    assert len(robot.nav_goals) == 2 and runner.running  # 2.7 m off: still walking there


def test_a_refused_viewpoint_is_skipped_with_its_turns() -> None:
    def refuse(goal: NavGoal) -> bool:
        return isinstance(goal, PoseGoal) and (goal.x, goal.y) == VIEWPOINTS[1]

    robot = FakeRobot(nav_refuse=refuse)
    runner = PatrolRunner(robot, fast_settings())
    runner.start(_route())
    _run(robot, runner, 200)
    assert runner.state == "done" and runner.detail == "1 viewpoint(s) skipped"
    assert _walks(robot) == [VIEWPOINTS[0], VIEWPOINTS[2]]
    assert len(robot.nav_goals) == 8


def test_navigation_refusing_with_a_typed_error_fails_the_patrol() -> None:
    robot = FakeRobot()
    runner = PatrolRunner(robot, fast_settings())
    runner.start(_route())

    def refuse(goal: NavGoal) -> str:  # navigation's ErrorReply: no goal at all
        raise Refused("unavailable: navigation has no map source", "unavailable")

    robot.send_nav_goal = refuse  # type: ignore[method-assign]
    _run(robot, runner, 20)
    assert (runner.state, runner.reason) == ("failed", "navigation_failed")
    assert robot.modes[-1] == ("stand", "navigation") and robot.arm_kinds() == ["look", "stow"]


def test_a_stop_cancels_the_goal_stows_the_arm_and_stands() -> None:
    robot = FakeRobot(nav_ticks=50)
    runner = PatrolRunner(robot, fast_settings())
    runner.start(_route())
    _run(robot, runner, 10)
    (goal_id,) = robot.active_nav_goals()
    runner.stop()
    (status,) = _run(robot, runner, 1)
    assert (status.state, status.detail, status.arm_look) == (
        "stopped",
        "stopped by a request",
        False,
    )
    assert robot.nav_cancels == [goal_id] and not robot.active_nav_goals()
    assert robot.arm_kinds() == ["look", "stow"]
    assert robot.modes[-1] == ("stand", "navigation")


def test_an_arm_not_in_look_in_time_walks_on_with_the_head_camera() -> None:
    robot = FakeRobot(arm_ticks=10**6)
    runner = PatrolRunner(robot, fast_settings())
    runner.start(_route())
    wait_ticks = round(ARM_WAIT_S * 1e9 / TICK_NS)
    statuses = _run(robot, runner, wait_ticks)
    assert robot.nav_goals == [] and robot.arm_kinds() == ["look"]
    statuses += _run(robot, runner, 2)
    assert len(robot.nav_goals) == 1 and not any(s.arm_look for s in statuses)
    assert runner.running


def test_a_stowed_patrol_sends_no_second_stow() -> None:
    robot = FakeRobot()
    runner = PatrolRunner(robot, fast_settings(patrol_arm_posture="stow"))  # type: ignore[arg-type]
    runner.start(_route())
    statuses = _run(robot, runner, 200)
    assert runner.state == "done" and robot.arm_kinds() == ["stow"]
    assert not any(s.arm_look for s in statuses)


# -- the plan -------------------------------------------------------------------------


def test_the_route_is_planned_on_the_maps_grid_with_a_viewpoint_near_each_support() -> None:
    cells = np.zeros((60, 120), np.uint8)  # a 12 × 6 m room, a bench against a wall
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    cells[1:7, 52:68] = OCCUPIED
    grid = OccupancyGrid(stamp_ns=0, resolution_m=0.1, origin_xy=(0.0, 0.0), cells=to_wire(cells))
    bench = SupportSurface("bench_1", (6.0, 0.4), (0.8, 0.3), 0.0, 0.9)
    robot = FakeRobot(grid=grid, xy=(2.0, 3.0))
    plain = plan_patrol(robot, fast_settings(patrol_spacing_m=4.0))
    robot.supports = [bench]
    near = plan_patrol(robot, fast_settings(patrol_spacing_m=4.0))
    assert isinstance(plain, Route) and isinstance(near, Route)
    assert len(near.viewpoints) > len(plain.viewpoints)
    assert min(float(np.hypot(v[0] - 6.0, v[1] - 0.4)) for v in near.viewpoints) <= 1.6


def test_the_semantic_pass_faces_the_maps_surfaces_or_walks_the_lattice_without_any() -> None:
    cells = np.zeros((60, 120), np.uint8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    cells[1:7, 52:68] = OCCUPIED
    grid = OccupancyGrid(stamp_ns=0, resolution_m=0.1, origin_xy=(0.0, 0.0), cells=to_wire(cells))
    robot = FakeRobot(grid=grid, xy=(2.0, 3.0))
    said: list[str] = []
    lattice = plan_patrol(robot, fast_settings(patrol_spacing_m=4.0), say=said.append,
                          surfaces=True)  # fmt: skip
    assert isinstance(lattice, Route) and lattice.facings is None
    assert said == ["no surface to look at from the known floor: the viewpoints' lattice"]
    robot.supports = [SupportSurface("surface_1", (6.0, 0.4), (0.8, 0.3), 0.0, 0.9)]
    facing = plan_patrol(robot, fast_settings(), say=said.append, surfaces=True)
    assert isinstance(facing, Route) and facing.facings is not None
    assert 1 <= len(facing.viewpoints) <= 2 and said[-1].startswith("semantic pass: ")


def test_no_grid_or_no_free_space_is_a_typed_refusal() -> None:
    robot = FakeRobot(map_up=False)
    refused = plan_patrol(robot, fast_settings())
    assert not isinstance(refused, Route) and refused.reason == "unavailable"
    full = np.full((20, 20), OCCUPIED, np.uint8)
    grid = OccupancyGrid(stamp_ns=0, resolution_m=0.1, origin_xy=(-1.0, -1.0), cells=to_wire(full))
    refused = plan_patrol(FakeRobot(grid=grid), fast_settings())
    assert not isinstance(refused, Route) and refused.reason == "no_route"


# -- the desk: requests, one job at a time --------------------------------------------


def key_of(name: str) -> str:
    return f"dume/alive/b1/{name}"


class Rig:
    """The fetch's desk and the patrol's, ticked as the node does."""

    def __init__(self) -> None:
        self.robot = small_world()
        self.lifelines = Lifelines()
        for name in DEPENDENCIES:
            self.lifelines.up(key_of(name))
        logger = MissionLogger(rr.RecordingStream("test", default_enabled=False), LOG)
        self.tree = MissionTree(context(self.robot))
        self.patrol = PatrolDesk(
            PatrolRunner(self.robot, fast_settings(), logger.patrol),
            self.robot,
            fast_settings(),
            Dependencies(self.lifelines, DEPENDENCIES, key_of, grace_s=0.0, link_grace_s=0.0),
            logger,
            LOG,
            answer_s=5.0,
        )
        self.requests = RequestInbox()
        self.sent: list[MissionStatus] = []
        self.desk = Desk(
            self.tree,
            self.robot,
            Dependencies(self.lifelines, DEPENDENCIES, key_of, grace_s=0.0, link_grace_s=0.0),
            StatusBoard(round(100 * 1e9)),
            self.requests,
            Inbox(),
            logger,
            self.sent.append,
            LOG,
            self.patrol.busy_with,
        )
        self.published: list[PatrolStatus] = []

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            b = self.robot.now_ns
            changed = self.desk.step(b)
            request = self.tree.request
            self.patrol.step(b, f"mission {request.request_id} is running" if request else "")
            self.robot.advance()
            self.desk.flush(b, changed)
            self.published.append(self.patrol.published(b))

    def ask(self, action: str) -> PatrolStatus:
        """A request as the queryable gets it, answered by the loop's next tick."""
        answer: list[PatrolStatus] = []
        asker = threading.Thread(
            target=lambda: answer.append(self.patrol.ask(PatrolRequest(action=action), ""))  # type: ignore[arg-type]
        )
        asker.start()
        while not self.patrol.pending:
            time.sleep(0.001)
        self.tick()  # the loop's next tick takes it and answers
        asker.join()
        return answer[0]


def test_a_patrol_is_answered_by_the_loop_and_published_every_tick() -> None:
    rig = Rig()
    rig.tick()
    assert rig.patrol.ask(PatrolRequest(action="status"), "").state == "idle"
    started = rig.ask("start")
    assert started.state == "running" and started.waypoints > 0
    rig.tick(5)
    assert all(s.state == "running" for s in rig.published[-5:])
    assert [s.stamp_ns for s in rig.published[-2:]] == [
        rig.robot.now_ns - 2 * TICK_NS,
        rig.robot.now_ns - TICK_NS,
    ]
    assert rig.ask("start").state == "rejected"  # one patrol at a time
    stopped = rig.ask("stop")
    assert stopped.state == "stopped"
    assert rig.robot.modes[-1] == ("stand", "navigation")


def test_a_fetch_and_a_patrol_refuse_each_other_busy() -> None:
    rig = Rig()
    rig.tick()
    rig.requests.submit(MissionRequest(request_id="r1", object="bottle_1", person="person_1"), "")
    rig.tick(3)
    refused = rig.ask("start")
    assert (refused.state, refused.reason) == ("rejected", "busy")
    assert "mission r1 is running" in refused.detail
    rig.tree.cancel("test")
    rig.tick()
    assert rig.ask("start").state == "running"
    rig.requests.push(encode(MissionRequest(request_id="r2", object="bottle_1", person="person_1")))
    rig.tick()
    assert (rig.sent[-1].request_id, rig.sent[-1].state, rig.sent[-1].reason) == (
        "r2",
        "rejected",
        "busy",
    )
    assert rig.sent[-1].detail == "a mapping patrol is running"


@pytest.mark.parametrize("lost", [False, True])
def test_a_dependency_down_refuses_a_patrol_and_one_lost_fails_it(lost: bool) -> None:
    rig = Rig()
    rig.tick()
    if not lost:
        rig.lifelines.down(key_of("navigation"))
        refused = rig.ask("start")
        assert (refused.state, refused.reason) == ("rejected", "unavailable")
        return
    assert rig.ask("start").state == "running"
    rig.lifelines.down(key_of("navigation"))
    rig.tick()
    assert (rig.published[-1].state, rig.published[-1].reason) == ("failed", "dependency_lost")
    assert rig.robot.modes[-1] == ("stand", "navigation")


def test_a_request_the_loop_never_takes_times_out() -> None:
    rig = Rig()
    rig.patrol.answer_s = 0.05
    with pytest.raises(RequestError) as err:
        rig.patrol.ask(PatrolRequest(action="start"), "")
    assert err.value.code == "timeout"
    rig.tick()
    assert rig.published[-1].state == "idle"  # dropped: never started


def test_a_runner_that_raises_fails_the_patrol_internal_and_the_loop_goes_on() -> None:
    rig = Rig()
    rig.tick()
    assert rig.ask("start").state == "running"

    def broken() -> None:
        raise RuntimeError("a bug")

    rig.patrol.runner.step = broken  # type: ignore[method-assign]
    rig.tick()
    assert (rig.published[-1].state, rig.published[-1].reason) == ("failed", "internal")
    assert rig.robot.modes[-1] == ("stand", "navigation")  # ended as safely as it could
