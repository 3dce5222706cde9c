"""The mapping patrol's route (`services.mission.coverage`) and its pose goals
(`services.mission.patrol_goals`): how the patrol moves on when navigation answers, the
viewpoints the floor plan's tables and benches add, a route over the small world, the
known floor as the only floor, the semantic pass's viewpoints facing the surfaces."""

from __future__ import annotations

import itertools
import math

import numpy as np

from common.grid import occupied_near
from common.messages import as_numpy
from common.messages.world import OCCUPIED, SupportSurface
from services.mission.coverage import Route, coverage_route, facing_route, support_targets
from services.mission.frontiers import UNKNOWN
from services.mission.patrol_goals import NavPatrol, patrol_goals
from services.sim.world import generate_world


def _route() -> Route:
    a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    b = np.array([[2.0, 0.0], [2.0, 1.0], [2.0, 2.0]])
    return Route([a[-1], b[-1]], [a, b])


def test_each_viewpoint_is_a_walk_facing_along_the_path_then_turns_round_the_circle() -> None:
    goals = patrol_goals(_route(), start_yaw=0.3, turns=3)
    assert len(goals) == 8
    walk, *turns = goals[:4]
    assert not walk.look and (walk.x, walk.y) == (2.0, 0.0)
    assert math.isclose(walk.yaw, 0.0, abs_tol=1e-9)  # along +x, the path's last stretch
    assert all(t.look and (t.x, t.y) == (2.0, 0.0) for t in turns)
    yaws = [walk.yaw] + [t.yaw for t in turns]
    steps = [math.remainder(b - a, math.tau) for a, b in itertools.pairwise(yaws)]
    assert np.allclose(steps, [2 * math.pi / 3] * 3)  # the full circle, one way
    assert math.isclose(goals[4].yaw, math.pi / 2)  # the second leg goes along +y
    assert [g.look for g in patrol_goals(_route(), 0.0, turns=0)] == [False, False]


def test_a_refused_or_failed_walk_skips_its_viewpoint_and_a_failed_turn_is_passed_over() -> None:
    p = NavPatrol(_route(), patrol_goals(_route(), 0.0, turns=3))
    p.sent("nav_1")
    p.finished(succeeded=True)
    assert p.current is not None and p.current.look and p.goal_id == ""
    p.sent("nav_2")
    p.finished(succeeded=False, reason="failed: blocked")
    assert p.index == 2 and p.skipped == 0  # the next turn, at the same viewpoint
    p.finished(True)
    p.finished(True)
    assert p.viewpoint == 2 and not p.current.look
    p.refused("invalid_goal: off the map")
    assert p.done and p.skipped == 1
    assert any("viewpoint 2 skipped" in line for line in p.log)


def test_the_patrol_counts_the_path_it_walked() -> None:
    p = NavPatrol(_route(), patrol_goals(_route(), 0.0))
    for x, y in [(0.0, 0.0), (3.0, 0.0), (3.0, 4.0)]:
        p.moved_to(x, y)
    assert math.isclose(p.travelled_m, 7.0)


def test_support_targets_run_along_each_tops_long_centre_line() -> None:
    bench = SupportSurface("bench_1", (1.0, 2.0), (0.1, 0.5), 0.0, 0.9)  # long along y
    pts = support_targets([bench], step_m=0.5)
    assert np.allclose(pts[:, 0], 1.0)
    assert np.allclose(pts[:, 1], [1.5, 2.0, 2.5])


def test_a_top_the_lattice_leaves_too_far_gets_a_viewpoint_within_see_m() -> None:
    # A 12 × 6 m room (10 cm cells) with a 1.6 × 0.6 m bench against the middle of the
    # bottom wall; lattice viewpoints every 4 m leave its top 2+ m away.
    cells = np.zeros((60, 120), np.uint8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    cells[1:7, 52:68] = OCCUPIED
    target = np.array([[6.0, 0.4]])
    plain = coverage_route(cells, 0.1, (0.0, 0.0), (2.0, 3.0), 4.0, 0.5)
    far = min(float(np.linalg.norm(v - target[0])) for v in plain.viewpoints)
    assert far > 1.6
    route = coverage_route(cells, 0.1, (0.0, 0.0), (2.0, 3.0), 4.0, 0.5, target, 1.6)
    near = min(float(np.linalg.norm(v - target[0])) for v in route.viewpoints)
    assert near <= 1.6 and len(route.viewpoints) == len(plain.viewpoints) + 1
    # every path still ends at its viewpoint and starts where the last one ended
    for a, b in zip(route.paths, route.paths[1:], strict=False):
        assert np.allclose(a[-1], b[0])


def test_the_route_over_the_small_world_keeps_off_obstacles_and_joins_up() -> None:
    w = generate_world(0, "small")
    g = w.occupancy
    cells = np.asarray(as_numpy(g.cells), np.uint8)
    start = (w.robot_start.x, w.robot_start.y)
    route = coverage_route(cells, g.resolution, g.origin, start, 2.5, 0.7)
    assert len(route.viewpoints) >= 3
    occupied = cells == OCCUPIED
    for path, vp in zip(route.paths, route.viewpoints, strict=True):
        assert not occupied_near(occupied, g.resolution, g.origin, path, 0.0).any()
        assert np.allclose(path[-1], vp)
    for a, b in itertools.pairwise(route.paths):
        assert np.allclose(a[-1], b[0])
    assert float(np.hypot(*(route.paths[0][0] - np.array(start)))) < 0.2


def _room() -> np.ndarray:
    """A 12 × 6 m room (10 cm cells), walls round it."""
    cells = np.zeros((60, 120), np.uint8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    return cells


def test_floor_the_map_does_not_know_is_no_floor_to_patrol() -> None:
    cells = _room()
    cells[:, 60:] = UNKNOWN  # the right half never seen
    route = coverage_route(cells, 0.1, (0.0, 0.0), (2.0, 3.0), 2.0, 0.5)
    assert route.viewpoints
    # every viewpoint keeps the clearance from the unknown as from a wall
    assert all(v[0] <= 6.0 - 0.5 for v in route.viewpoints)
    assert all((p[:, 0] <= 6.0 - 0.5).all() for p in route.paths)


def test_the_semantic_pass_faces_each_surface_from_within_range_with_few_viewpoints() -> None:
    cells = _room()
    cells[1:7, 52:68] = OCCUPIED  # a 1.6 × 0.6 m bench against the bottom wall
    cells[35:45, 20:35] = OCCUPIED  # a 1.5 × 1 m table in the room
    bench = SupportSurface("surface_1", (6.0, 0.4), (0.8, 0.3), 0.0, 0.9)
    table = SupportSurface("surface_2", (2.75, 4.0), (0.75, 0.5), 0.0, 0.7)
    half_fov = math.radians(30)
    targets = support_targets([bench, table])
    route = facing_route(cells, 0.1, (0.0, 0.0), (9.0, 3.0), targets, 0.5, 0.8, 1.6, half_fov)
    assert route.unseen == 0 and route.facings is not None
    assert 2 <= len(route.viewpoints) < len(targets)  # a viewpoint sees several targets
    for t in targets:  # each target: some viewpoint sees it within range, in its view
        assert any(
            0.8 <= float(np.linalg.norm(t - v)) <= 1.6
            and abs(math.remainder(math.atan2(t[1] - v[1], t[0] - v[0]) - f, math.tau))
            <= half_fov + 1e-9
            for v, f in zip(route.viewpoints, route.facings, strict=True)
        )
    # the goals: one walk per viewpoint arriving at its facing, no turning round
    goals = patrol_goals(route, 0.0, turns=3)
    assert [g.look for g in goals] == [False] * len(route.viewpoints)
    assert [g.yaw for g in goals] == route.facings
    for a, b in itertools.pairwise(route.paths):
        assert np.allclose(a[-1], b[0])


def test_a_surface_seen_only_through_a_wall_is_unseen() -> None:
    cells = _room()
    cells[:, 60] = OCCUPIED  # a wall splits the room; the robot is on the left
    shelf = SupportSurface("surface_1", (7.0, 3.0), (0.5, 0.2), math.pi / 2, 0.9)
    cells[25:35, 68:72] = OCCUPIED
    route = facing_route(
        cells, 0.1, (0.0, 0.0), (2.0, 3.0), support_targets([shelf]), 0.5, 0.8, 1.6, 0.5
    )
    assert route.viewpoints == [] and route.unseen == len(support_targets([shelf]))


def test_the_viewpoint_stands_out_of_peoples_way_where_another_sees_as_well() -> None:
    """A table in the middle of the room, seen from either side: people walk past its
    south side (the busy places), so its viewpoint stands on the north side; with people
    on both sides the table is still looked at, from the busy floor."""
    cells = _room()
    cells[27:33, 50:70] = OCCUPIED  # a 2 × 0.6 m table, long along x, at (6, 3)
    table = SupportSurface("table_1", (6.0, 3.0), (1.0, 0.3), 0.0, 0.75)
    targets = support_targets([table])
    args = (cells, 0.1, (0.0, 0.0), (1.0, 3.0), targets, 0.5, 0.8, 1.6, math.radians(35))
    plain = facing_route(*args)
    south = np.array([[x, 1.6] for x in np.arange(3.0, 9.5, 1.0)])  # an aisle at y = 1.6
    north = south + np.array([0.0, 2.8])  # and one at y = 4.4
    quiet = facing_route(*args, south)
    assert plain.unseen == quiet.unseen == 0
    assert quiet.viewpoints and all(v[1] > 3.0 for v in quiet.viewpoints)  # the north side
    assert all(min(np.hypot(*(v - b)) for b in south) > 1.0 for v in quiet.viewpoints)
    both = facing_route(*args, np.vstack([south, north]))
    assert both.unseen == 0 and both.viewpoints  # nowhere quiet: looked at all the same
    assert any(v[1] < 3.0 for v in plain.viewpoints)  # without them: in the south aisle
