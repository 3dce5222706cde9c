"""The exploration on the mission's port, without Zenoh (`mission_fakes.FakeRobot`).

A room the fake robot senses as it goes (`SensedRoom`: the map learns the room's cells
within 2 m of wherever the robot stood when the map was read, never those within 0.9 m of
it there, as the head camera): `ExploreRunner` steps off the unknown floor it starts on
by itself (a turn on the spot, a walk onto seen floor), walks frontier after frontier,
blacklists what navigation refuses, ends done with the room known, or on its budget.
Then through the desks as the node ticks them: a request of task `explore` on
`mission/status` with its stage and progress, cancelled, busy against a fetch, and a
patrol asked for by request.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgspec
import numpy as np
from numpy.typing import NDArray

from common.messages import encode, to_wire
from common.messages.mission import MissionCancel, MissionRequest, MissionStatus
from common.messages.navigation import NavGoal, PoseGoal
from common.messages.semantic_map import MapEntity, OccupancyGrid
from common.messages.world import FREE, OCCUPIED, SupportSurface
from common.robot import Footprint
from services.mission.explore import ExploreRunner
from services.mission.frontiers import UNKNOWN
from services.mission.patrol import in_doubt
from services.mission.patrol_desk import PatrolDesk
from tests.unit.mission_fakes import TICK_NS, FakeRobot, fast_settings
from tests.unit.test_mission_patrol import LOG, Rig, key_of

RES = 0.1
FP = Footprint(front=0.52, back=0.62, half_width=0.24)


@dataclass
class SensedRoom:
    """An 8 × 6 m room with a table, on a 12 × 10 m grid nobody has seen yet."""

    truth: NDArray[np.uint8]
    known: NDArray[np.bool_]
    reads: int = 0

    @classmethod
    def make(cls) -> SensedRoom:
        truth = np.full((100, 120), UNKNOWN, np.uint8)  # outside the room: never seen
        truth[20:80, 20:100] = OCCUPIED
        truth[21:79, 21:99] = FREE
        truth[45:55, 70:85] = OCCUPIED  # a table
        return cls(truth, np.zeros(truth.shape, bool))

    def __call__(self, robot: FakeRobot) -> OccupancyGrid:
        self.reads += 1
        iy, ix = np.mgrid[0 : self.truth.shape[0], 0 : self.truth.shape[1]]
        d = np.hypot((ix + 0.5) * RES - 2.0 - robot.xy[0], (iy + 0.5) * RES - 2.0 - robot.xy[1])
        self.known |= (d > 0.9) & (d < 2.0)
        cells = np.where(self.known, self.truth, UNKNOWN).astype(np.uint8)
        return OccupancyGrid(
            stamp_ns=robot.t, resolution_m=RES, origin_xy=(-2.0, -2.0), cells=to_wire(cells)
        )

    def known_free_m2(self) -> float:
        return float(np.sum(self.known & (self.truth == FREE))) * RES * RES


def explorer(robot: FakeRobot, **settings: float) -> ExploreRunner:
    return ExploreRunner(robot, fast_settings(**settings), LOG.info, FP)


def run(robot: FakeRobot, job: ExploreRunner, ticks: int) -> int:
    """Step the job until it ends or `ticks` passed; the ticks it ran."""
    for n in range(ticks):
        if not job.running:
            return n
        job.step()
        robot.advance()
    return ticks


def test_from_nothing_it_steps_off_unknown_floor_then_explores_the_room_until_done() -> None:
    room = SensedRoom.make()
    robot = FakeRobot(xy=(2.0, 3.0), moves=True, occupancy_of=room)
    job = explorer(robot)
    job.start()
    run(robot, job, 5000)
    assert job.state == "done", (job.reason, job.detail)
    assert job.detail.startswith("no reachable frontier left")
    # Its own cmd_vel first (turn, then walk off the unknown floor), navigation after.
    assert robot.modes[:3] == [("walk", "navigation"), ("walk", "mission"), ("walk", "navigation")]
    assert robot.modes[-1] == ("stand", "navigation")
    assert robot.arm_kinds() == ["stow"]  # stowed while exploring: no second stow either
    walks = [g for _id, g in robot.nav_goals if isinstance(g, PoseGoal)]
    assert len(walks) == 4 * job.tally.chosen  # each goal: a walk and three turns
    assert job.tally.chosen >= 3 and not job.tally.failed
    free_m2 = float(np.sum(room.truth == FREE)) * RES * RES
    assert room.known_free_m2() > 0.9 * free_m2  # the room is known
    status = job.status(robot.t)
    assert (status.task, status.state, status.waypoint) == ("explore", "done", job.tally.chosen)
    assert status.known_m2 > 0.9 * free_m2 and status.travelled_m > 3.0
    assert job.progress() < 1.0


def test_a_goal_navigation_refuses_is_left_out_and_another_is_chosen() -> None:
    room = SensedRoom.make()
    refused: list[tuple[float, float]] = []

    def refuse(goal: NavGoal) -> bool:  # the first walk goal on known floor, once
        if isinstance(goal, PoseGoal) and not refused:
            refused.append((goal.x, goal.y))
            return True
        return False

    robot = FakeRobot(xy=(2.0, 3.0), moves=True, occupancy_of=room, nav_refuse=refuse)
    job = explorer(robot)
    job.start()
    run(robot, job, 5000)
    assert job.state == "done" and job.tally.failed == refused
    chosen = [(g.x, g.y) for _id, g in robot.nav_goals if isinstance(g, PoseGoal)]
    assert all(math.dist(c, refused[0]) > 0.5 for c in chosen)


def test_its_budget_of_goals_ends_it_failed_with_what_it_did() -> None:
    room = SensedRoom.make()
    robot = FakeRobot(xy=(2.0, 3.0), moves=True, occupancy_of=room)
    job = explorer(robot, explore_max_goals=2)
    job.start()
    run(robot, job, 5000)
    assert (job.state, job.reason) == ("failed", "budget")
    assert job.detail.startswith("its budget of 2 goals ran out: 2 goal(s) walked of 2")
    assert robot.modes[-1] == ("stand", "navigation") and not robot.active_nav_goals()


def test_goals_that_add_too_little_floor_end_it_done_with_what_they_added() -> None:
    room = SensedRoom.make()
    robot = FakeRobot(xy=(2.0, 3.0), moves=True, occupancy_of=room)
    job = explorer(robot, explore_stall_goals=2, explore_stall_m2=1000.0)  # never enough
    job.start()
    run(robot, job, 5000)
    assert job.state == "done" and job.reason == ""
    assert job.detail.startswith("the last 2 goals added ") and "less than 1000" in job.detail
    assert job.tally.chosen == 2 and len(job.tally.known) == 3
    everything = explorer(robot, explore_stall_goals=0, explore_stall_m2=1000.0)
    everything.start()
    run(robot, everything, 5000)
    assert everything.detail.startswith("no reachable frontier left")


def test_its_budget_of_sim_time_ends_it_even_during_a_goal() -> None:
    robot = FakeRobot(xy=(2.0, 3.0), moves=True, occupancy_of=SensedRoom.make(), nav_ticks=10**6)
    job = explorer(robot, explore_max_s=30.0)
    job.start()
    ticks = run(robot, job, 5000)
    assert (job.state, job.reason) == ("failed", "budget") and ticks <= 30 * 20 + 2
    assert robot.nav_cancels and not robot.active_nav_goals()


def test_no_grid_fails_it_unavailable_and_no_floor_to_step_onto_no_route() -> None:
    robot = FakeRobot(map_up=False)
    job = explorer(robot)
    job.start()
    run(robot, job, 50)
    assert (job.state, job.reason) == ("failed", "unavailable")
    walled = np.full((60, 60), UNKNOWN, np.uint8)
    walled[5:55, 5:55] = OCCUPIED  # it sees nothing but obstacles round it

    def grid(r: FakeRobot) -> OccupancyGrid:
        return OccupancyGrid(stamp_ns=0, resolution_m=0.1, origin_xy=(-3.0, -3.0),
                             cells=to_wire(walled))  # fmt: skip

    robot = FakeRobot(moves=True, occupancy_of=grid)
    job = explorer(robot)
    job.start()
    run(robot, job, 2000)
    assert (job.state, job.reason) == ("failed", "no_route")


# -- through the desks: requests, status, cancel, one job at a time ----------------------


class ExploreRig(Rig):
    """The node's desks with an explorer in the sensed room."""

    def __init__(self, **settings: float) -> None:
        super().__init__()
        self.room = SensedRoom.make()
        self.robot.xy, self.robot.moves, self.robot.occupancy_of = (2.0, 3.0), True, self.room
        old, m = self.patrol, fast_settings(**settings)
        self.patrol = PatrolDesk(
            old.runner, self.robot, m, old.deps, old.log, LOG, answer_s=5.0,
            explorer=ExploreRunner(self.robot, m, LOG.info, FP),
        )  # fmt: skip
        self.desk.jobs = self.patrol
        self.desk.busy_with = self.patrol.busy_with

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            b = self.robot.now_ns
            changed = self.desk.step(b)
            request = self.tree.request
            self.patrol.step(b, f"mission {request.request_id} is running" if request else "")
            changed |= self.desk.job_status(b)
            self.robot.advance()
            self.desk.flush(b, changed)
            self.published.append(self.patrol.published(b))

    def of(self, request_id: str) -> list[MissionStatus]:
        return [s for s in self.sent if s.request_id == request_id]


def test_an_explore_request_runs_on_mission_status_with_its_stage_until_it_succeeds() -> None:
    rig = ExploreRig()
    rig.tick()
    rig.requests.push(b'{"request_id": "x1", "task": "explore"}')
    for _ in range(200):
        rig.tick(25)
        if rig.sent[-1].state == "succeeded":
            break
    ours = rig.of("x1")
    assert [s.state for s in ours[:2]] == ["accepted", "running"]
    assert {s.behaviour for s in ours} == {"explore"}
    assert ours[-1].state == "succeeded" and ours[-1].progress == 1.0
    assert "no reachable frontier left" in ours[-1].detail
    progress = [s.progress for s in ours if s.state == "running"]
    assert progress == sorted(progress) and len(progress) > 2
    assert rig.published[-1].task == "explore" and rig.published[-1].state == "done"


def test_an_explore_is_cancelled_by_its_request_id_and_blocks_a_fetch_meanwhile() -> None:
    rig = ExploreRig(patrol_clearance_m=0.3)  # the patrol after it: on the floor seen by then
    rig.tick()
    rig.requests.push(encode(MissionRequest(request_id="x1", task="explore")))
    rig.tick(40)
    rig.requests.push(encode(MissionRequest(request_id="f1", object="bottle_1", person="person_1")))
    rig.requests.push(encode(MissionRequest(request_id="x2", task="explore")))
    rig.tick()
    assert [(s.state, s.reason, s.detail) for s in rig.of("f1")] == [
        ("rejected", "busy", "an exploration is running")
    ]
    assert [(s.state, s.reason) for s in rig.of("x2")] == [("rejected", "busy")]
    assert rig.ask("start").state == "rejected"  # nor a patrol on mission/patrol
    rig.desk.cancels.push(encode(MissionCancel(request_id="x1", reason="enough")))
    rig.tick()
    assert (rig.of("x1")[-1].state, rig.of("x1")[-1].reason) == ("cancelled", "cancelled")
    assert rig.robot.modes[-1] == ("stand", "navigation") and not rig.robot.active_nav_goals()
    rig.requests.push(encode(MissionRequest(request_id="p1", task="patrol")))
    rig.tick(2)
    assert [s.state for s in rig.of("p1")] == ["accepted", "running"]
    assert rig.of("p1")[-1].behaviour == "patrol" and rig.published[-1].task == "patrol"


def test_a_request_during_a_fetch_is_busy_and_a_fetch_without_a_person_malformed() -> None:
    rig = ExploreRig()
    rig.tick()
    rig.requests.push(b'{"request_id": "f0", "object": "bottle_1"}')
    rig.requests.push(encode(MissionRequest(request_id="f1", object="bottle_1", person="person_1")))
    rig.requests.push(b'{"request_id": "x1", "task": "explore"}')
    rig.tick()
    (f0,) = rig.of("f0")
    assert (f0.state, f0.reason) == ("rejected", "malformed") and "person" in f0.detail
    assert (rig.of("x1")[-1].state, rig.of("x1")[-1].reason) == ("rejected", "busy")
    assert "mission f1 is running" in rig.of("x1")[-1].detail


def _explore_to_the_end(rig: ExploreRig) -> tuple[list[MissionStatus], list[str]]:
    """An explore request run to its end: its statuses and the stages it ran through."""
    rig.tick()
    rig.requests.push(encode(MissionRequest(request_id="x1", task="explore")))
    for _ in range(400):
        rig.tick(25)
        if rig.sent[-1].state in ("succeeded", "failed"):
            break
    ours = rig.of("x1")
    return ours, [s.behaviour for s in ours if s.state == "running"]


def test_with_the_semantic_pass_the_patrol_walks_the_explored_map_for_the_same_request() -> None:
    rig = ExploreRig(explore_semantic_pass=True)
    # the table as the map saw it: the pass faces it, and does not turn round
    rig.robot.supports = [SupportSurface("surface_1", (5.75, 3.0), (0.75, 0.5), 0.0, 0.8)]
    ours, stages = _explore_to_the_end(rig)
    assert stages[0] == "explore" and stages[-1] == "semantic_pass"
    assert ours[-1].state == "succeeded", ours[-1]
    assert ours[-1].detail.startswith("explored: no reachable frontier left")
    assert rig.robot.arm_kinds()[-2:] == ["look", "stow"]  # the patrol's arm, then stowed
    assert rig.published[-1].task == "patrol" and rig.published[-1].state == "done"
    walker = rig.patrol.runner.walker
    assert walker is not None and walker.route.facings is not None
    assert 1 <= len(walker.route.viewpoints) <= 4 and not any(g.look for g in walker.goals)
    for v, yaw in zip(walker.route.viewpoints, walker.route.facings, strict=True):
        to_table = math.atan2(3.0 - v[1], 5.75 - v[0])
        assert abs(math.remainder(yaw - to_table, math.tau)) < math.radians(45)


def test_after_the_semantic_pass_it_looks_again_from_near_at_an_artifact_seen_from_afar() -> None:
    rig = ExploreRig(explore_semantic_pass=True)
    rig.robot.supports = [SupportSurface("surface_1", (5.75, 3.0), (0.75, 0.5), 0.0, 0.8)]
    far = MapEntity(id="box_1", class_name="box", kind="artifact",
                    position_in_world=(5.4, 2.6, 0.85), uncertainty_m=0.05, last_seen_ns=0,
                    source="perception", observations=40, nearest_view_m=3.6)  # fmt: skip
    near = msgspec.structs.replace(
        far, id="can_1", class_name="can", position_in_world=(6.3, 3.4, 0.85), nearest_view_m=1.2
    )
    rig.robot.artifacts = {"box_1": far, "can_1": near}
    ours, stages = _explore_to_the_end(rig)
    assert stages[-1] == "second_look" and "semantic_pass" in stages
    assert ours[-1].state == "succeeded", ours[-1]
    route = rig.patrol.runner.walker.route  # type: ignore[union-attr]
    assert route.facings is not None and len(route.viewpoints) == 1  # the box only
    v, yaw = route.viewpoints[0], route.facings[0]
    assert 0.8 <= math.dist(v, (5.4, 2.6)) <= 1.3
    assert abs(math.remainder(yaw - math.atan2(2.6 - v[1], 5.4 - v[0]), math.tau)) < 0.05


def test_what_is_in_doubt_is_what_the_map_saw_only_from_afar_a_few_times_or_two_ways() -> None:
    def art(i: str, cls: str, xy: tuple[float, float], near: float | None,
            source: str = "perception", seen: int = 40) -> MapEntity:  # fmt: skip
        return MapEntity(id=i, class_name=cls, kind="artifact", position_in_world=(*xy, 0.8),
                         uncertainty_m=0.05, last_seen_ns=0, source=source,  # type: ignore[arg-type]
                         nearest_view_m=near, observations=seen)  # fmt: skip

    m = fast_settings()
    arts = [
        art("box_1", "box", (0.0, 0.0), 3.1),  # only from afar
        art("can_1", "can", (2.0, 0.0), 1.0),  # a can and a bottle 12 cm apart: one object
        art("bottle_1", "bottle", (2.12, 0.0), 1.1),
        art("bottle_2", "bottle", (4.0, 0.0), 1.0),  # fine
        art("bottle_3", "bottle", (6.0, 0.0), None, source="prior"),  # not the map's own
        art("can_2", "can", (6.1, 0.0), 4.0, source="prior"),
        art("box_2", "box", (8.0, 0.0), 1.7, seen=2),  # twice from near: a false entry?
        art("box_3", "box", (10.0, 0.0), 1.7, seen=10),  # fine
    ]
    doubt = in_doubt(arts, m)
    assert doubt == {"box_1": "seen only from 3.1 m", "can_1": "0.12 m from bottle_1",
                     "bottle_1": "0.12 m from can_1", "box_2": "seen 2 times"}  # fmt: skip


def test_a_dependency_lost_while_no_tick_comes_fails_the_exploration_at_once() -> None:
    rig = ExploreRig()
    rig.tick()
    rig.requests.push(encode(MissionRequest(request_id="x1", task="explore")))
    rig.tick(10)
    rig.lifelines.down(key_of("navigation"))
    b = rig.robot.now_ns - TICK_NS  # the last tick: the clock stopped after it
    assert rig.desk.stalled(b)
    rig.desk.flush(b, True)
    last = rig.of("x1")[-1]
    assert (last.state, last.reason, last.stamp_ns) == ("failed", "dependency_lost", b)
    assert "navigation" in last.detail and rig.robot.modes[-1] == ("stand", "navigation")
