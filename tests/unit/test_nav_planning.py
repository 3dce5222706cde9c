"""Navigation's pure planning: A* against Dijkstra, failures with reasons, goal poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from common.config import NavigationSettings, PeopleSettings, PlannerSettings
from common.messages import world
from common.robot import HANDOVER_DISTANCE_M
from services.navigation import native
from services.navigation.costmap import CostParams, Person, build_costmap
from services.navigation.goals import GoalError, handover_pose, standoff_pose
from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint, footprint_free
from services.navigation.people import TRACKING_MARGIN, people_limit
from services.navigation.planner import PlanError, plan, pose_ok
from services.sim import feasibility as fz
from services.sim.world import generate_world

FP = Footprint.stowed()


def test_the_install_built_the_c_search() -> None:
    # `make install` builds it (setup.py); the scipy fallback is for machines without cc.
    assert native.compiled()


@pytest.mark.parametrize("seed", range(8))
def test_astar_cost_equals_dijkstra_on_random_grids(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ny, nx = rng.integers(10, 60, 2)
    cost = rng.uniform(0.0, 1.0, (ny, nx)).astype(np.float32)
    cost[rng.random((ny, nx)) < 0.2] = -1.0
    cost[0, 0] = cost[-1, -1] = 0.0
    found = native.search(cost, (0, 0), (int(ny) - 1, int(nx) - 1), 4.0)
    reference = dijkstra(native.grid_graph(cost, 4.0), indices=0)[-1]
    if math.isinf(reference):
        assert len(found.cells) == 0
    else:
        assert found.cost == pytest.approx(reference, rel=1e-9)
        steps = np.abs(np.diff(found.cells, axis=0)).max(axis=1)
        assert np.all(steps == 1) and np.all(cost[found.cells[:, 0], found.cells[:, 1]] >= 0)


def _room(walls: list[tuple[slice, slice]]) -> Grid:
    occ = np.zeros((120, 160), dtype=bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    for ys, xs in walls:
        occ[ys, xs] = True
    return Grid(occ, 0.05, (0.0, 0.0))


def test_a_goal_behind_a_closed_wall_is_refused_with_no_path() -> None:
    cm = build_costmap(_room([(slice(None), slice(78, 82))]), FP, CostParams())
    with pytest.raises(PlanError) as err:
        plan(cm, Pose(1.5, 3.0, 0.0), Pose(6.5, 3.0, 0.0), FP, PlannerSettings())
    assert err.value.reason == "no_path"


def test_a_gap_closed_by_a_person_fails_naming_the_people_near() -> None:
    walled = _room([(slice(0, 80), slice(78, 82))])  # the gap is at the room's top
    free = build_costmap(walled, FP, CostParams())
    plan(free, Pose(1.5, 3.0, 0.0), Pose(6.5, 3.0, 0.0), FP, PlannerSettings())
    person = Person("person_9", 4.0, 5.0)  # standing in the gap
    blocked = build_costmap(walled, FP, CostParams(), people=[person])
    with pytest.raises(PlanError) as err:
        plan(blocked, Pose(3.2, 4.4, 0.0), Pose(6.5, 3.0, 0.0), FP, PlannerSettings())
    assert err.value.reason == "no_path" and "people near: person_9 at 1.00 m" in str(err.value)


def test_a_plan_goes_around_a_wall_through_its_gap() -> None:
    cm = build_costmap(_room([(slice(0, 80), slice(78, 82))]), FP, CostParams())
    result = plan(cm, Pose(1.5, 1.5, 0.0), Pose(6.5, 1.5, 0.0), FP, PlannerSettings())
    assert result.poses[:, 1].max() > 4.0  # through the gap at y > 4 m
    iy, ix, _ = cm.grid.cells(result.poses[:, :2])
    assert np.all(cm.cost[iy, ix] >= 0)


def test_a_goal_in_an_obstacle_moves_to_the_nearest_free_pose() -> None:
    cm = build_costmap(_room([(slice(50, 70), slice(70, 90))]), FP, CostParams())
    goal = Pose(4.0, 3.0, 0.0)  # the block's centre
    result = plan(cm, Pose(1.5, 3.0, 0.0), goal, FP, PlannerSettings(goal_search_m=1.5))
    moved = math.hypot(result.goal.x - goal.x, result.goal.y - goal.y)
    assert 0.0 < moved <= 1.5
    assert footprint_free(cm.occupied, cm.grid, result.goal, FP, 0.03)
    with pytest.raises(PlanError) as err:
        plan(cm, Pose(1.5, 3.0, 0.0), goal, FP, PlannerSettings(goal_search_m=0.2))
    assert err.value.reason == "invalid_goal"


def _world_costmap(name: str, seed: int):  # type: ignore[no-untyped-def]
    world = generate_world(seed, name)
    people = [Person(p.id, p.position[0], p.position[1], p.yaw) for p in world.people]
    return world, build_costmap(Grid.from_world(world.occupancy), FP, CostParams(), people=people)


@pytest.mark.parametrize(("name", "seed"), [("small", 1), ("hall", 3), ("hall", 5)])
def test_standoff_poses_are_free_and_face_their_artifact(name: str, seed: int) -> None:
    world, cm = _world_costmap(name, seed)
    for a in world.artifacts:
        pose = standoff_pose(cm, a.position[0], a.position[1], FP)
        assert footprint_free(cm.occupied, cm.grid, pose, FP, 0.03)
        bearing = math.atan2(a.position[1] - pose.y, a.position[0] - pose.x)
        assert abs(math.remainder(bearing - pose.yaw, math.tau)) < 1e-6
        truth = fz.standoff_pose(world, a.id)  # what the world generator aims for
        assert abs(math.remainder(pose.yaw - truth.yaw, math.tau)) < 0.35


def test_an_explored_bench_standoff_faces_its_front_not_the_strip_behind_its_lidar_band() -> None:
    """As hall seed 0's explored bench: the lidar saw a 15 cm band of the bench's front
    (occupied), one row of free cells behind it (beams under the top), then unknown; the
    can on the band. The way out is the front, 15 cm away, not the strip 1 cm behind."""
    cells = np.full((120, 160), world.FREE, dtype=np.uint8)
    cells[:40, 40:100] = 255  # unknown: under and behind the bench, never seen
    cells[39, 40:100] = world.FREE  # the strip behind the band
    cells[40:43, 40:100] = world.OCCUPIED  # the band: the bench's front panel
    occ = cells != world.FREE
    grid = Grid(occ, 0.05, (0.0, 0.0), cells == world.OCCUPIED)
    cm = build_costmap(grid, FP, CostParams())
    can = (3.5, 40.5 * 0.05)  # on the band's back row
    pose = standoff_pose(cm, *can, FP)
    assert abs(pose.x - can[0]) < 0.05 and pose.y > can[1] + 0.9  # out in front of it
    assert math.remainder(pose.yaw + math.pi / 2, math.tau) == pytest.approx(0.0, abs=0.02)


def test_a_standoff_asked_for_on_given_sides_stands_near_one_or_says_where_it_tried() -> None:
    """Hall seed 1's box_2, 19 cm tall near table_2's edge, its long faces 27° off the
    table's long side: held from the side only with the line of sight along them. Of
    that line's two ends one lies on the table; the stance is near the other."""
    world, cm = _world_costmap("hall", 1)
    box = next(a for a in world.artifacts if a.id == "box_2")
    x, y = box.position[:2]
    along = box.yaw  # the box's x (its long side: half sizes 6.9 × 3.0 cm)
    tol = math.radians(30.0)
    pose = standoff_pose(cm, x, y, FP, bearings=(along, along + math.pi), tolerance=tol)
    assert footprint_free(cm.occupied, cm.grid, pose, FP, 0.03)
    bearing = math.atan2(pose.y - y, pose.x - x)  # from the box to the robot
    assert abs(math.remainder(bearing - (along + math.pi), math.tau)) <= tol + 1e-6
    assert abs(math.remainder(math.atan2(y - pose.y, x - pose.x) - pose.yaw, math.tau)) < 1e-6
    # the default stands off the table's nearest edge, further from that line
    default = standoff_pose(cm, x, y, FP)
    off = abs(math.remainder(math.atan2(default.y - y, default.x - x) - along, math.pi))
    assert off > tol
    # asked only for the end on the table: refused, saying what it tried
    with pytest.raises(GoalError, match=r"within 5° of -27°: .* meets .* the map's obstacles"):
        standoff_pose(cm, x, y, FP, bearings=(along,), tolerance=math.radians(5.0))


@pytest.mark.parametrize(("name", "seed"), [("small", 1), ("hall", 1), ("hall", 3)])
def test_handover_poses_are_free_and_face_their_person(name: str, seed: int) -> None:
    _, cm = _world_costmap(name, seed)
    for person in cm.people:
        pose = handover_pose(cm, person, (0.0, 0.0), FP)
        assert footprint_free(cm.occupied, cm.grid, pose, FP, 0.03)
        assert pose_ok(cm, pose, FP, 0.03), "the planner takes the pose as it is"
        bearing = math.atan2(person.y - pose.y, person.x - pose.x)
        assert abs(math.remainder(bearing - pose.yaw, math.tau)) < 1e-6
        assert math.hypot(person.x - pose.x, person.y - pose.y) == pytest.approx(
            HANDOVER_DISTANCE_M, abs=0.01
        )
        # held out from farther (`PersonHandover.extra_m`: a long object in the gripper)
        far = handover_pose(cm, person, (0.0, 0.0), FP, distance=HANDOVER_DISTANCE_M + 0.08)
        assert pose_ok(cm, far, FP, 0.03)
        assert math.hypot(person.x - far.x, person.y - far.y) == pytest.approx(
            HANDOVER_DISTANCE_M + 0.08, abs=0.01
        )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_handover_pose_near_a_wall_is_one_the_planner_accepts(seed: int) -> None:
    """The map's person positions are noisy: wherever the person is, a handover pose that
    `handover_pose` gives is one `plan` takes as it is (no `invalid_goal` on arrival)."""
    _, cm = _world_costmap("small", seed)
    rng = np.random.default_rng(seed)
    tried = 0
    for person in cm.people:
        for _ in range(20):
            p = Person(person.id, person.x + rng.normal(0, 0.3), person.y + rng.normal(0, 0.3))
            try:
                pose = handover_pose(cm, p, (0.0, 0.0), FP)
            except GoalError:
                continue
            tried += 1
            assert pose_ok(cm, pose, FP, 0.03), (p, pose)
    assert tried >= 10


def test_people_slow_the_robot_and_stop_it_when_close_ahead() -> None:
    p, top = PeopleSettings(), 0.6  # a base whose top speed is 0.6 m/s
    pose = Pose(0.0, 0.0, 0.0)
    ahead = lambda x: [Person("person_1", x, 0.0)]  # noqa: E731
    assert people_limit(pose, (1.0, 0.0), ahead(5.0), FP, p, top).rule == ""
    slow = people_limit(pose, (1.0, 0.0), ahead(FP.front + 1.5), FP, p, top)
    assert slow.rule == "slow" and slow.speed == pytest.approx(p.slow_speed * (1 - TRACKING_MARGIN))
    stop = people_limit(pose, (1.0, 0.0), ahead(FP.front + 0.4), FP, p, top)
    assert stop.rule == "stop" and stop.speed == 0.0
    leaving = people_limit(pose, (-1.0, 0.0), ahead(FP.front + 0.4), FP, p, top)
    assert leaving.rule == "slow"
    handing = people_limit(pose, (1.0, 0.0), ahead(FP.front + 1.0), FP, p, top, "person_1")
    assert handing.rule == "handover"
    assert handing.speed == pytest.approx(p.handover_speed * (1 - TRACKING_MARGIN))
    d = distance_to_footprint(pose, FP, np.array([[FP.front + 0.5, 0.0]]))
    assert d[0] == pytest.approx(0.5)


def test_a_walker_coming_from_behind_stops_a_walking_robot_earlier() -> None:
    """Hall seed 0's shift (t = 46.6 s): a walker at 1.1 m/s came from behind-left of a
    robot walking on 119° away from them; the stop at S_p at rest left the trot's sway
    0.15 m/s towards them inside S_p. The base needs `stopping_s` to come to rest: the
    stop comes that much earlier for them, not for someone standing, nor for a robot
    already at rest."""
    p, top = PeopleSettings(), 0.6
    pose = Pose(0.0, 0.0, 0.0)
    away = (math.cos(math.radians(-61.0)), math.sin(math.radians(-61.0)))  # 119° off them
    x = -FP.back - 1.6  # 1.6 m behind the footprint, walking at it
    walker = [Person("person_4", x, 0.0, None, (1.1, 0.0))]
    plain = people_limit(pose, away, walker, FP, p, top)
    assert plain.rule != "stop" and plain.protective_m < 1.6  # S_p at rest: 1.38 m
    early = people_limit(pose, away, walker, FP, p, top, stopping_s=0.5)
    assert early.rule == "stop" and early.speed == 0.0
    standing = [Person("person_4", -FP.back - 0.65, 0.0, None, (0.0, 0.0))]  # S_p 0.61
    assert people_limit(pose, away, standing, FP, p, top, stopping_s=0.5).rule != "stop"
    passing = [Person("person_4", x, 0.0, None, (0.0, 1.1))]  # across, not at it
    assert people_limit(pose, away, passing, FP, p, top, stopping_s=0.5).rule != "stop"


def test_a_stop_for_a_walker_still_coming_holds_though_the_path_leads_away() -> None:
    """Hall seed 4's shift (t = 277.8 s): a walker at 1.13 m/s came at the robot from
    behind; inside S_p at rest the path leading away let it walk on at the slow zone's
    speed between stops, every 0.1-0.2 s, and the sway took the base towards them. Once
    stopped for someone still coming, it stays at rest; a person standing there, or one
    it no longer stops early for (a stale velocity), may still be walked away from."""
    p, top = PeopleSettings(), 0.6
    pose = Pose(0.0, 0.0, 0.0)
    away = (1.0, 0.0)  # straight away from someone behind
    walker = [Person("person_4", -FP.back - 1.0, 0.0, None, (1.1, 0.0))]
    assert people_limit(pose, away, walker, FP, p, top).rule == "slow"  # first: away
    held = people_limit(pose, away, walker, FP, p, top, stopped=True)
    assert held.rule == "stop" and held.speed == 0.0
    standing = [Person("person_4", -FP.back - 0.5, 0.0, None, (0.0, 0.0))]
    assert people_limit(pose, away, standing, FP, p, top, stopped=True).rule == "slow"
    stale = people_limit(pose, away, walker, FP, p, top, stopped=True, not_early={"person_4"})
    assert stale.rule == "slow"
    passing = [Person("person_4", -FP.back - 1.0, 0.0, None, (0.0, 1.1))]  # across
    assert people_limit(pose, away, passing, FP, p, top, stopped=True).rule == "slow"


def test_an_idle_navigator_ticks_at_rest_without_a_goal() -> None:
    from services.navigation.navigator import Navigator

    nav = Navigator(FP, NavigationSettings(), 0.05)
    cm = build_costmap(_room([]), FP, CostParams())
    out = nav.tick(0, Pose(1.0, 1.0, 0.0), cm)
    assert out.state == "idle"
    assert not np.any(out.cmd)


def test_a_held_path_stays_until_another_is_clearly_cheaper_or_it_is_lethal() -> None:
    """Two equal ways round a block: a person's cost that makes the held way a little
    dearer does not swap it (the crossroads to and fro), one that makes it much dearer
    does, and so does the held way becoming lethal, or the goal being blocked."""
    from services.navigation.navigator import GoalSpec, Navigator

    block = _room([(slice(40, 80), slice(70, 90))])  # y 2-4 m, x 3.5-4.5 m
    start, goal = Pose(1.5, 3.0, 0.0), Pose(6.5, 3.0, 0.0)
    at = lambda x, y: build_costmap(block, FP, CostParams(), people=[Person("p", x, y)])  # noqa: E731
    above = lambda nav: float(nav.plan.poses[:, 1].mean()) > 3.0  # noqa: E731
    ns = NavigationSettings(blocked_timeout_s=10.0)  # it stands still: not blocked yet
    dt = round(ns.replan_s * 1.1e9)
    nav = Navigator(FP, ns, 0.05)
    nav.start(GoalSpec("g", goal, 0.1, 0.1), 0)
    nav.tick(0, start, at(4.0, 0.4))  # a person near the way below: above
    assert above(nav)
    a_little = at(6.2, 5.95)  # near the way above: A* alone would go below now
    assert plan(a_little, start, goal, FP, ns.planner).poses[:, 1].mean() < 3.0
    out = nav.tick(dt, start, a_little)
    assert out.new_plan is None and above(nav)
    out = nav.tick(2 * dt, start, at(6.0, 5.9))  # the way above dearer by a quarter
    assert out.new_plan is not None and not above(nav)
    nav.tick(3 * dt, start, at(6.2, 0.05))  # the mirror of a little: held below
    assert not above(nav)
    out = nav.tick(4 * dt, start, at(4.0, 1.4))  # standing on the way below, far ahead
    assert out.new_plan is not None and above(nav)
    nav.tick(12 * dt, start, a_little)  # no progress for 10 s: blocked, then
    nav.tick(13 * dt, start, a_little)  # a blocked goal takes any new plan
    assert not above(nav)


def test_heights_are_measured_from_the_floor_the_frame_shows() -> None:
    """The base's estimated pitch is 1.5° off: in the world the floor rises 10 cm at
    4 m, over the 8 cm an obstacle needs. From the fitted floor, only the box stands."""
    from services.navigation.depth import DepthParams, heights_above_floor

    xs, ys = np.meshgrid(np.linspace(0.5, 4.0, 40), np.linspace(-1.5, 1.5, 20))
    floor = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    bx, by = np.meshgrid(np.linspace(2.4, 2.6, 5), np.linspace(-0.2, 0.2, 8))
    box = np.column_stack([bx.ravel(), by.ravel(), np.full(bx.size, 0.3)])
    pts = np.vstack([floor, box])
    pitch = math.radians(-1.5)  # about the camera at (0, 0, 0.6): what a wrong tilt does
    c, s = math.cos(pitch), math.sin(pitch)
    rel = pts - [0.0, 0.0, 0.6]
    seen = np.column_stack(
        [c * rel[:, 0] + s * rel[:, 2], rel[:, 1], -s * rel[:, 0] + c * rel[:, 2]]
    )
    seen += [0.0, 0.0, 0.6]
    p = DepthParams()
    assert np.max(seen[: len(floor), 2]) > p.min_height_m  # phantom obstacles on z alone
    h = heights_above_floor(seen, p)
    assert np.max(np.abs(h[: len(floor)])) < 0.01
    assert np.allclose(h[len(floor) :], 0.3, atol=0.02)
    # Too little floor in view: the world's z.
    np.testing.assert_array_equal(heights_above_floor(seen[-60:], p), seen[-60:, 2])


def test_a_handover_pose_takes_the_side_asked_for_before_the_persons_front() -> None:
    """The mission's search round a person of unknown facing asks for a side: that side,
    whichever way the person faces or the robot stands (or the nearest free one)."""
    _, cm = _world_costmap("hall", 1)
    person = cm.people[0]
    front = handover_pose(cm, person, (0.0, 0.0), FP)
    asked = math.remainder(math.atan2(front.y - person.y, front.x - person.x) + 2.0, math.tau)
    pose = handover_pose(cm, person, (0.0, 0.0), FP, bearing=asked)
    side = math.atan2(pose.y - person.y, pose.x - person.x)
    assert abs(math.remainder(side - asked, math.tau)) < math.radians(45)  # that side, or near
    assert pose_ok(cm, pose, FP, 0.03)
    assert math.hypot(person.x - pose.x, person.y - pose.y) == pytest.approx(
        HANDOVER_DISTANCE_M, abs=0.01
    )


def _drive(nav, pose: Pose, cm, seconds: float, t0_ns: int = 0):  # type: ignore[no-untyped-def]
    """Tick `nav` at 20 Hz from `t0_ns`, the base going where it is sent (body frame),
    until the goal ends or `seconds` pass; the last output and pose, and the next tick."""
    out, k = None, 0
    for k in range(round(seconds / 0.05)):
        out = nav.tick(t0_ns + round(k * 0.05e9), pose, cm)
        vx, vy, wz = out.cmd
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        pose = Pose(pose.x + (c * vx - s * vy) * 0.05, pose.y + (s * vx + c * vy) * 0.05,
                    pose.yaw + wz * 0.05)  # fmt: skip
        if out.state != "active":
            break
    return out, pose, t0_ns + round((k + 1) * 0.05e9)


def test_a_robot_stopped_by_a_person_standing_too_near_steps_away_and_goes_on() -> None:
    """Seed 0's shift began a request 0.68 m from the worker it had just handed to and
    stood 46 s and two recoveries: within a bystander's S_p at rest only a way clearly
    away from them may move. After `blocked_timeout_s` it steps straight away from
    them, then walks round them to its goal."""
    from services.navigation.navigator import STEP_AWAY_S, GoalSpec, Navigator

    start, goal = Pose(2.0, 3.0, 0.0), Pose(6.0, 3.0, 0.0)
    at = (2.0 + FP.front + 0.1, 3.0 + FP.half_width + 0.35)  # ahead, to the left
    cm = build_costmap(_room([]), FP, CostParams(), people=[Person("p", *at, None, (0.0, 0.0))])
    ns = NavigationSettings()
    nav = Navigator(FP, ns, 0.05)
    nav.start(GoalSpec("g", goal, 0.1, 0.1), 0)
    assert nav.tick(0, start, cm).limit.rule == "stop"
    out, end, t = _drive(nav, start, cm, 2.0 * ns.blocked_timeout_s + STEP_AWAY_S)
    assert out.recovery == "" and nav.stepped == {"p"}
    assert distance_to_footprint(end, FP, np.array([at]))[0] > 0.61 + 0.15  # S_p at rest, margin
    assert nav.recoveries == ["clear", "rotate", "backoff"]  # none of those used
    out, end, _ = _drive(nav, end, cm, 40.0, t)
    assert out.state == "succeeded", out.detail
