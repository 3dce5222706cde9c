"""Frontier-based exploration's choice of goal (`services.mission.frontiers`) on synthetic
grids: a room half unknown, a corridor, a frontier behind a wall, a failed goal, a room
fully known, the robot on floor nobody saw, specks and places already looked from."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from common.messages.world import FREE, OCCUPIED
from services.mission.frontiers import (
    UNKNOWN,
    FrontierParams,
    Survey,
    clearance,
    frontier_clusters,
    frontier_mask,
    step_out_target,
    survey,
)

RES = 0.05
ORIGIN = (0.0, 0.0)


def room(w_m: float, h_m: float) -> NDArray[np.uint8]:
    """A room w × h m of free floor (its corner at the origin), walled by one cell."""
    cells = np.full((round(h_m / RES), round(w_m / RES)), FREE, np.uint8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    return cells


def cell(x: float, y: float) -> tuple[int, int]:
    return math.floor(y / RES), math.floor(x / RES)


def clear_of_non_free(cells: NDArray[np.uint8], x: float, y: float) -> float:
    return float(clearance(cells == FREE, RES)[cell(x, y)])


def test_in_a_room_half_unknown_the_goal_faces_the_unknown_half_from_seen_floor() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN  # x > 4 m nobody saw
    out = survey(cells, RES, ORIGIN, (1.0, 2.0))
    g = out.goal
    assert g is not None and out.robot_on_known and out.clusters == out.reachable == 1
    assert g.x < 4.0 and 1.0 <= 4.0 - g.x <= 2.1  # seen floor, 1-2 m from the frontier
    assert abs(g.yaw) < 0.2  # facing +x, the unknown half
    assert clear_of_non_free(cells, g.x, g.y) >= 0.7  # room to turn on the spot
    assert math.isclose(g.path_m, math.hypot(g.x - 1.0, g.y - 2.0), rel_tol=0.1, abs_tol=0.1)
    assert math.isclose(out.known_free_m2, float(np.sum(cells == FREE)) * RES * RES)
    assert math.isclose(g.frontier_m, 3.9, abs_tol=0.15)  # the whole width, walls left out


def test_in_a_corridor_the_goal_is_along_it_facing_its_unknown_end() -> None:
    cells = np.full((40, 200), OCCUPIED, np.uint8)  # 10 × 2 m, a 1.6 m corridor along x
    cells[4:36, :] = FREE
    cells[4:36, 100:] = UNKNOWN
    out = survey(cells, RES, ORIGIN, (1.0, 1.0))
    g = out.goal
    assert g is not None
    assert 3.0 <= g.x <= 4.05 and abs(g.y - 1.0) < 0.15 and abs(g.yaw) < 0.2


def test_a_frontier_behind_a_wall_is_no_goal() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80] = OCCUPIED  # a wall without a door at x = 4 m
    cells[:, 130:] = UNKNOWN  # the far room's end, seen over the wall, is unknown
    out = survey(cells, RES, ORIGIN, (1.0, 2.0))
    assert out.clusters == 0 and out.reachable == 0 and out.goal is None


def test_free_cells_behind_a_walls_face_are_no_frontier() -> None:
    """The small world's walls as the explored map had them: the two cells of the face
    the sensors hit occupied, a cell behind them free (a beam that ended inside the wall),
    the unknown beyond it; a door in the face makes the strip the robot's own floor."""
    cells = room(8.0, 4.0)
    cells[:, 150:] = UNKNOWN  # outside the room, east of x = 7.5 m
    cells[1:-1, 146:148] = OCCUPIED  # the wall's face
    cells[1:-1, 148:150] = FREE  # inside the wall, marked free
    cells[1:-1, 145] = FREE
    out = survey(cells, RES, ORIGIN, (2.0, 2.0))
    assert out.robot_on_known and out.clusters == 0 and out.goal is None
    cells[30:50, 146:148] = FREE  # a door 1 m wide in the face: the strip is this floor
    out = survey(cells, RES, ORIGIN, (2.0, 2.0))
    assert out.clusters == 1 and out.goal is not None


def test_a_goal_that_failed_is_not_chosen_again_nor_one_near_it() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN
    params = FrontierParams(blacklist_m=0.5)
    first = survey(cells, RES, ORIGIN, (1.0, 2.0), params).goal
    assert first is not None
    again = survey(cells, RES, ORIGIN, (1.0, 2.0), params, failed=[(first.x, first.y)]).goal
    assert again is not None
    assert math.hypot(again.x - first.x, again.y - first.y) > 0.5
    # Every seeing place failed: no goal is left, and that is said.
    everywhere = [(x, y) for x in np.arange(0.0, 4.0, 0.2) for y in np.arange(0.0, 4.0, 0.2)]
    assert survey(cells, RES, ORIGIN, (1.0, 2.0), params, failed=everywhere).goal is None


def test_a_room_fully_known_has_no_frontier() -> None:
    out = survey(room(8.0, 4.0), RES, ORIGIN, (1.0, 2.0))
    assert out == Survey(None, 0, 0, out.known_free_m2, True, [])


def test_a_robot_standing_on_floor_nobody_saw_has_no_goal_but_knows_why() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN
    cells[30:50, 10:30] = UNKNOWN  # where the robot stands (the camera never sees there)
    out = survey(cells, RES, ORIGIN, (1.0, 2.0))
    assert out.goal is None and not out.robot_on_known and out.clusters >= 1


def test_specks_of_unknown_in_seen_floor_and_short_frontiers_are_no_frontier() -> None:
    cells = room(8.0, 4.0)
    cells[20, 20] = cells[40:42, 60:62] = UNKNOWN  # depth samples missed
    assert not frontier_mask(cells, RES, 0.1).any()
    cells[10:12, 0] = UNKNOWN  # a gap in a wall: 2 cells of frontier, 0.1 m
    mask = frontier_mask(cells, RES, 0.1)
    assert mask.any() and frontier_clusters(mask, RES, 0.3) == []
    assert survey(cells, RES, ORIGIN, (1.0, 2.0)).goal is None


def test_what_a_look_around_left_unseen_near_it_is_not_a_frontier_any_more() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN
    looked = [(3.5, 2.0)]
    near = survey(cells, RES, ORIGIN, (1.0, 2.0), FrontierParams(seen_m=1.2), looked=looked)
    far = survey(cells, RES, ORIGIN, (1.0, 2.0), FrontierParams(seen_m=5.0), looked=looked)
    assert near.clusters == 2 and near.goal is not None  # the ends of the frontier are left
    assert far.clusters == 0 and far.goal is None


def test_the_goal_prefers_a_long_frontier_to_a_slightly_nearer_short_one() -> None:
    cells = room(12.0, 6.0)
    cells[:, 200:] = UNKNOWN  # a long frontier at x = 10 m (6 m of it)
    cells[:1, 20:34] = UNKNOWN  # a short gap in the wall nearer the robot, 0.7 m
    out = survey(cells, RES, ORIGIN, (4.0, 3.0), FrontierParams(gain=2.0))
    assert out.goal is not None and out.goal.x > 7.5
    short = survey(cells, RES, ORIGIN, (4.0, 3.0), FrontierParams(gain=0.0))
    assert short.goal is not None and short.goal.x < 3.0


def test_a_robot_on_unknown_floor_steps_out_onto_the_nearest_clear_seen_floor() -> None:
    cells = np.full((80, 160), UNKNOWN, np.uint8)  # 8 × 4 m, nothing known but a ring
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    x, y = 2.0, 2.0
    iy, ix = np.mgrid[0:80, 0:160]
    d = np.hypot((ix + 0.5) * RES - x, (iy + 0.5) * RES - y)
    cells[(d > 0.9) & (d < 2.6) & (cells != OCCUPIED)] = FREE  # what one look-around saw
    target = step_out_target(cells, RES, ORIGIN, (x, y), pass_m=0.32, body_m=0.24)
    assert target is not None
    dist = math.hypot(target[0] - x, target[1] - y)
    assert 1.3 <= dist <= 1.5  # the ring's inner edge 0.9 m + 0.32 + 0.15 of clearance
    assert survey(cells, RES, ORIGIN, target).robot_on_known
    cells[(d > 0.9) & (d < 2.6)] = OCCUPIED  # nothing but obstacles around
    assert step_out_target(cells, RES, ORIGIN, (x, y), pass_m=0.32, body_m=0.24) is None


def test_a_step_out_never_crosses_an_occupied_cell() -> None:
    cells = room(8.0, 4.0)
    cells[30:50, 30:50] = UNKNOWN  # the robot's own cells at (2, 2)
    cells[:, 55] = OCCUPIED  # a wall 0.75 m to the robot's right (+x) ...
    cells[:, 25] = OCCUPIED  # ... and to its left; free beyond both, and along y
    target = step_out_target(cells, RES, ORIGIN, (2.0, 2.0), pass_m=0.32, body_m=0.24)
    assert target is not None and 1.65 < target[0] < 2.4  # along the corridor, not over a wall


def test_a_frontier_looked_at_that_stayed_is_not_aimed_at_again() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN
    cells[30:50, 70:79] = OCCUPIED  # a crate hides part of the frontier from the room
    first = survey(cells, RES, ORIGIN, (1.0, 2.0)).goal
    assert first is not None
    after = survey(cells, RES, ORIGIN, (first.x, first.y), looked=[(first.x, first.y)],
                   aimed=[first.aim_xy])  # fmt: skip
    assert after.goal is None or math.dist(after.goal.aim_xy, first.aim_xy) > 1.2


def test_frontiers_beyond_the_radius_to_explore_are_left() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN  # the frontier at x = 4 m
    near = survey(cells, RES, ORIGIN, (1.0, 2.0), within=((1.0, 2.0), 3.5))
    far = survey(cells, RES, ORIGIN, (1.0, 2.0), within=((1.0, 2.0), 2.5))
    assert near.goal is not None and far.clusters == 0 and far.goal is None


def test_frontiers_outside_the_site_outline_are_left() -> None:
    cells = room(8.0, 4.0)
    cells[:, 80:] = UNKNOWN  # the frontier at x = 4 m
    inside = survey(cells, RES, ORIGIN, (1.0, 2.0), bounds=(-1.0, -1.0, 6.0, 5.0))
    outside = survey(cells, RES, ORIGIN, (1.0, 2.0), bounds=(-1.0, -1.0, 3.8, 5.0))
    assert inside.goal is not None and outside.clusters == 0 and outside.goal is None
