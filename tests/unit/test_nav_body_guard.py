"""The body guard: a turn or a step that would sweep the footprint onto an obstacle is not
commanded (hall seed 0's shift: a turn in place beside a pallet ground the hips into it).

The scene: the base at the origin facing +x, a pallet-sized block behind its left side
(0.16 m from the footprint's side), and a path straight back to the west, past the block
(0.4 m from its centreline, the planner's clearance): the follower wants to turn round
first, and either way round a corner of the body swings into the block.
"""

from __future__ import annotations

import math

import numpy as np

from common.config import ControllerSettings, NavigationSettings
from services.navigation.body_guard import BodyGuard
from services.navigation.controller import Follower
from services.navigation.costmap import CostParams, build_costmap
from services.navigation.grid import Footprint, Grid, Pose, footprint_free
from services.navigation.navigator import GoalSpec, Navigator

DT = 0.05
FP = Footprint.stowed()
RES = 0.05
ORIGIN = (-3.0, -4.0)


def _grid(side: float = 1.0) -> Grid:
    """The block behind the base's left side (`side` −1: its right)."""
    occ = np.zeros((int(6.0 / RES), int(6.0 / RES)), dtype=bool)
    xs = ORIGIN[0] + (np.arange(occ.shape[1]) + 0.5) * RES
    ys = side * (ORIGIN[1] + (np.arange(occ.shape[0]) + 0.5) * RES)  # mirrored for −1
    block = (ys[:, None] >= 0.4) & (ys[:, None] <= 1.2) & (xs[None, :] >= -1.2)
    occ[block & (xs[None, :] <= 0.0)] = True
    return Grid(occ, RES, ORIGIN)


GRID = _grid()
COSTMAP = build_costmap(GRID, FP, CostParams())
START = Pose(0.0, 0.0, 0.0)


def _west() -> np.ndarray:
    xs = np.linspace(0.0, -2.0, 41)
    return np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, math.pi)])


def _step(pose: Pose, cmd: np.ndarray) -> Pose:
    vx, vy, wz = (float(v) for v in cmd)
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return Pose(pose.x + (c * vx - s * vy) * DT, pose.y + (s * vx + c * vy) * DT,
                math.remainder(pose.yaw + wz * DT, math.tau))  # fmt: skip


def _touches(pose: Pose) -> bool:
    return not footprint_free(COSTMAP.occupied, GRID, pose, FP, 0.0)


def _run(guarded: bool, ticks: int = 400) -> tuple[list[Pose], bool, list[str]]:
    f = Follower(_west(), ControllerSettings())
    pose, cmd, poses, said = START, np.zeros(3), [], []
    for _ in range(ticks):
        pose = _step(pose, cmd)  # the last tick's command acts now
        poses.append(pose)
        guard = BodyGuard(COSTMAP.solid, GRID, FP, pose) if guarded else None
        out = f.step(pose, DT, 0.0, math.inf, 0.1, 0.1, guard)
        cmd = out.cmd
        said.append(out.guarded)
        if out.arrived:
            return poses, True, said
    return poses, False, said


def test_the_scene_starts_free_and_an_unguarded_turn_sweeps_the_body_into_the_block() -> None:
    assert not _touches(START)
    poses, _, _ = _run(guarded=False)
    assert any(_touches(p) for p in poses)


def test_guarded_the_robot_walks_sideways_clear_of_the_block_then_turns_and_arrives() -> None:
    poses, arrived, said = _run(guarded=True)
    assert arrived
    assert said[0] == "unturned" and said[-1] == ""
    assert not [p for p in poses if _touches(p)]
    # It walked backwards along the path with its heading kept, and turned once clear.
    first_turned = next(k for k, p in enumerate(poses) if abs(p.yaw) > 0.1)
    assert poses[first_turned].x < -0.9


def test_free_stays_free_and_a_body_already_touching_may_only_move_off() -> None:
    guard = BodyGuard(COSTMAP.solid, GRID, FP, START)
    assert guard.now == 0
    assert not guard.ok((0.0, 0.0, -0.8))  # the rear corner swings into the block
    assert guard.ok((0.0, 0.0, 0.8))  # the front one reaches it only later:
    assert not guard.ok((0.0, 0.0, 0.8), math.pi)  # the whole turn round is refused
    assert guard.ok((-0.5, 0.0, 0.0))  # backwards, along it
    assert guard.ok((0.0, -0.3, 0.0))  # sideways, away from it
    assert guard.ok((0.0, 0.0, 0.0))
    inside = Pose(0.0, 0.3, 0.0)  # the rear corner already in the block
    touching = BodyGuard(COSTMAP.solid, GRID, FP, inside)
    assert touching.now > 0
    assert touching.ok((0.0, -0.3, 0.0))  # off it
    assert not touching.ok((0.0, 0.3, 0.0))  # further in


def test_the_rotate_recovery_turns_the_way_the_body_has_room_for() -> None:
    for side, way in ((1.0, 1.0), (-1.0, -1.0)):  # its default (anticlockwise), else the other
        grid = _grid(side)
        cm = build_costmap(grid, FP, CostParams())
        nav = Navigator(FP, NavigationSettings(), DT)
        nav.start(GoalSpec("g", Pose(3.0, 0.0, 0.0), 0.1, 0.1), 0)
        nav.recovery, nav.recovery_until = "rotate", 10**12
        out = nav.tick(1, START, cm)
        assert out.recovery == "rotate"
        assert math.copysign(1.0, out.cmd[2]) == way, side
        assert BodyGuard(cm.solid, grid, FP, START).ok(out.cmd)


def _post_grid() -> Grid:
    """A table leg (10 cm square) behind the base's left, 0.7 m from its centre."""
    occ = np.zeros((120, 120), dtype=bool)
    xs = -3.0 + (np.arange(120) + 0.5) * RES
    cx, cy = 0.7 * math.cos(2.4), 0.7 * math.sin(2.4)
    occ[(np.abs(xs[:, None] - cy) <= 0.05) & (np.abs(xs[None, :] - cx) <= 0.05)] = True
    return Grid(occ, RES, (-3.0, -3.0))


def test_a_turn_the_body_has_no_room_for_one_way_round_goes_the_other_way() -> None:
    # The goal: where the base stands, facing 1.5 rad to its right. Turning right swings
    # the rear-left corner into the leg; turning left the long way (4.8 rad) clears it.
    grid = _post_grid()
    cm = build_costmap(grid, FP, CostParams())
    guard = BodyGuard(cm.solid, grid, FP, START)
    assert guard.now == 0
    assert not guard.ok((0.0, 0.0, -0.5), -1.5) and guard.ok((0.0, 0.0, 0.5), -1.5 + math.tau)
    nav = Navigator(FP, NavigationSettings(), DT)
    nav.start(GoalSpec("g", Pose(0.0, 0.0, -1.5), 0.1, 0.1), 0)
    pose, cmd, said, recoveries = START, np.zeros(3), [], []
    for k in range(800):
        pose = _step(pose, cmd)
        out = nav.tick(int(k * DT * 1e9), pose, cm)
        cmd = out.cmd
        said.append(out.guarded)
        recoveries.append(out.recovery)
        assert footprint_free(cm.occupied, grid, pose, FP, 0.0), (k, pose)
        if out.state != "active":
            break
    assert out.state == "succeeded", out
    assert "the other way round" in said
    assert not any(recoveries)  # a long turn is progress, not a block
    assert abs(math.remainder(pose.yaw + 1.5, math.tau)) <= 0.1


def test_along_a_wall_the_guards_answer_is_kept_a_moment_not_flipped_each_tick() -> None:
    # A path 5 m along a wall 6 cm beyond the body's side, the pose seen with 1 cm and
    # 0.02 rad of noise: turns toward the wall are refused now and then.
    occ = np.zeros((120, 200), dtype=bool)
    occ[-3.0 + (np.arange(120) + 0.5) * RES >= 0.30, :] = True
    grid = Grid(occ, RES, (-3.0, -3.0))
    xs = np.linspace(0.0, 5.0, 101)
    f = Follower(np.column_stack([xs, 0.02 * np.sin(2.0 * xs), 0.0 * xs]), ControllerSettings())
    rng = np.random.default_rng(0)
    pose, cmd, said = START, np.zeros(3), []
    for _ in range(600):
        pose = _step(pose, cmd)
        seen = Pose(*(np.array([pose.x, pose.y, pose.yaw]) + rng.normal(0, [0.01, 0.01, 0.02])))
        out = f.step(seen, DT, 0.0, math.inf, 0.1, 0.1, BodyGuard(occ, grid, FP, seen))
        cmd, arrived = out.cmd, out.arrived
        said.append(out.guarded)
        assert footprint_free(occ, grid, pose, FP, 0.0), pose
        if arrived:
            break
    assert arrived and "unturned" in said
    assert len(said) * DT < 5.0 / ControllerSettings().v_max[0] + 3.0  # walked on, not crabbed
    back = [k for k in range(1, len(said)) if said[k] == "" and said[k - 1]]
    began = [k for k in range(1, len(said)) if said[k] == "unturned" and not said[k - 1]]
    # Each time back to the full command, the fallback had lasted GUARD_HOLD_S, 0.5 s (without
    # the hold, 1 or 2 ticks: 9 flips in 11 s).
    assert back
    for k in back:
        start = max(b for b in began if b < k)
        assert (k - start) * DT >= 0.4, (start, k)


def test_unknown_floor_is_no_obstacle_to_a_turn() -> None:
    # Exploring from nothing: a disc of seen floor 0.7 m round the base, unknown beyond
    # (the small world's first look round stood 57 s so). The body may swing over the
    # unknown; the planner still keeps the walk off it, and known obstacles still count
    # (`test_free_stays_free_...`).
    xs = -1.0 + (np.arange(40) + 0.5) * RES
    seen = np.hypot(xs[None, :], xs[:, None]) <= 0.7
    grid = Grid(~seen, RES, (-1.0, -1.0), np.zeros_like(seen))
    cm = build_costmap(grid, FP, CostParams())
    # Counted as obstacles, the unknown cells the body's corners reach refuse the turn.
    assert not BodyGuard(cm.occupied, grid, FP, START).ok((0.0, 0.0, 0.5), math.pi / 2)
    nav = Navigator(FP, NavigationSettings(), DT)
    nav.start(GoalSpec("g", Pose(0.0, 0.0, math.pi / 2), 0.1, 0.1), 0)
    pose, cmd = START, np.zeros(3)
    for k in range(200):
        pose = _step(pose, cmd)
        out = nav.tick(int(k * DT * 1e9), pose, cm)
        cmd = out.cmd
        assert out.guarded == "" and out.recovery == "", (k, out)
        if out.state != "active":
            break
    assert out.state == "succeeded", out


def test_an_align_with_no_room_to_turn_walks_to_the_goals_own_point_and_turns_there() -> None:
    # A patrol's look round: the goal's point has room to turn, but the loose tolerance
    # let the base stop 0.36 m short of it, its back 2 cm from a post: either way round a
    # rear corner meets the post.
    occ = np.zeros((80, 80), dtype=bool)
    xs = -2.0 + (np.arange(80) + 0.5) * RES
    occ[np.ix_(np.abs(xs) <= 0.05, (xs >= -0.7) & (xs <= -0.65))] = True
    grid = Grid(occ, RES, (-2.0, -2.0))
    cm = build_costmap(grid, FP, CostParams())
    guard = BodyGuard(cm.solid, grid, FP, START)
    assert guard.now == 0
    assert not guard.ok((0.0, 0.0, 0.5), math.pi / 2)
    assert not guard.ok((0.0, 0.0, -0.5), math.pi / 2 - math.tau)
    nav = Navigator(FP, NavigationSettings(), DT)
    nav.start(GoalSpec("g", Pose(0.36, 0.0, math.pi / 2), 0.4, 0.1), 0)
    pose, cmd, said = START, np.zeros(3), []
    for k in range(600):
        pose = _step(pose, cmd)
        out = nav.tick(int(k * DT * 1e9), pose, cm)
        cmd = out.cmd
        said.append(out.guarded)
        assert out.recovery == "", (k, out)
        assert footprint_free(cm.solid, grid, pose, FP, 0.0), (k, pose)
        if out.state != "active":
            break
    assert out.state == "succeeded", out
    assert said[0] == "unturned" and pose.x > 0.05  # in as far as it took to turn


def test_what_is_near_says_how_many_cells_of_which_layer_and_where_the_nearest_is() -> None:
    import re

    from services.navigation.body_guard import what_is_near

    static = GRID.occupied  # the block 0.16 m beside the body's left side at START
    assert what_is_near(static, static, GRID, FP, START) == "nothing within 0.10 m"
    solid = static.copy()
    cell = GRID.cell(0.53, 0.03)  # a depth cell just beyond the body's front
    assert cell is not None
    solid[cell] = True
    said = what_is_near(solid, static, GRID, FP, START)
    assert said.startswith("1 cells within 0.10 m (0 the map's, 1 the depth's)"), said
    ahead, left = (float(v) for v in re.findall(r"([+-]\d\.\d\d) m (?:ahead|left)", said))
    assert abs(ahead - 0.525) < 0.006 and abs(left - 0.025) < 0.006, said
    moved = what_is_near(solid, static, GRID, FP, Pose(0.0, 0.1, 0.0))  # 6 cm from the block
    mapped, depth = (
        int(v) for v in re.findall(r"\((\d+) the map's, (\d+) the depth's\)", moved)[0]
    )
    assert mapped > 0 and depth == 1, moved


def _bench_on_the_right() -> Grid:
    """A bench along the body's right side from x −1.5 to 1.5, its face 1 cm beyond the
    side at START (inside the guard's 2 cm margin: the body touches it)."""
    occ = np.zeros((int(6.0 / RES), int(6.0 / RES)), dtype=bool)
    xs = ORIGIN[0] + (np.arange(occ.shape[1]) + 0.5) * RES
    ys = ORIGIN[1] + (np.arange(occ.shape[0]) + 0.5) * RES
    face = -(FP.half_width + 0.01)
    occ[(ys[:, None] <= face - 0.5 * RES) & (ys[:, None] >= face - 0.6)
        & (np.abs(xs[None, :]) <= 1.5)] = True  # fmt: skip
    return Grid(occ, RES, ORIGIN)


def test_a_body_touching_a_bench_with_no_turn_either_way_steps_clear_of_it() -> None:
    """Hall seed 5: 2-3 cm along a bench, a turn either way sweeps a corner into it and
    there is no walk on: the guard stood until the goal failed. It steps away from the
    bench instead, until there is room to turn."""
    grid = _bench_on_the_right()
    cm = build_costmap(grid, FP, CostParams())
    guard = BodyGuard(cm.solid, grid, FP, START)
    assert guard.now > 0
    assert not guard.ok((0.0, 0.0, -0.5), -1.0) and not guard.ok((0.0, 0.0, 0.5), 2 * math.pi - 1.0)
    away = guard.away()
    assert away is not None and away[1] > 0.95  # to the left, off the bench
    f = Follower(_west(), ControllerSettings())
    label, cmd, _turn = f._guarded(guard, np.array([0.0, 0.0, -0.5]), (0.0, 0.0), -1.0, DT)
    assert label == "step clear" and abs(cmd[0]) < 0.03 and cmd[1] > 0.09 and cmd[2] == 0.0
    pose = START
    for _ in range(30):  # 1.5 s at 0.1 m/s: 15 cm to the left
        pose = _step(pose, cmd)
    clear = BodyGuard(cm.solid, grid, FP, pose)
    assert clear.now == 0  # no longer touching, and still short of room to turn:
    step = clear.away()
    assert step is not None and step[1] > 0.95  # it steps on away from the bench
    roomy = BodyGuard(cm.solid, grid, FP, Pose(0.0, 0.5, 0.0))
    assert roomy.away() is None  # 0.5 m off: room enough, nothing to step from
    assert roomy.ok((0.0, 0.0, -0.5), -1.0)  # and the turn is let through


def test_a_body_stepping_clear_for_a_turn_does_not_walk_back_before_it_turns() -> None:
    """Hall seed 2's shift: at a goal whose own point lay towards a machine by the body's
    back corner, the guard stepped clear of it for the turn, then let the walk back to
    the goal's point through (unturned), then stepped clear again: 34 s back and forth
    5 cm, never turning. Stepping clear, it steps until it can turn, then turns."""
    grid = _bench_on_the_right()
    cm = build_costmap(grid, FP, CostParams())
    f = Follower(_west(), ControllerSettings())
    pose, said = Pose(0.0, 0.02, 0.0), []
    for _ in range(200):  # 10 s: the goal's point towards the bench, its yaw 1 rad right
        guard = BodyGuard(cm.solid, grid, FP, pose)
        err = math.remainder(-1.0 - pose.yaw, math.tau)
        label, cmd, _turn = f._guarded(guard, np.array([0.0, 0.0, 1.5 * err]), (0.0, -0.09),
                                       err, DT)  # fmt: skip
        said.append(label)
        pose = _step(pose, cmd)
    first = said.index("step clear")
    turned = [k for k, w in enumerate(said) if k > first and w != "step clear"]
    assert turned and said[turned[0]] in ("", "turn only", "the other way round"), said
    assert abs(math.remainder(-1.0 - pose.yaw, math.tau)) < 0.1, pose


def _table_scene() -> tuple[Grid, Pose, Pose]:
    """A table's edge along y = 0 (x −1.5..0.8), a shelf's along y = 1.25 (x −1.5..1.0),
    a standoff 0.57 m from the table facing it, and the robot 3 m along the edge facing
    the way to the standoff: between them the rear corners (0.69 m from the base, with
    the guard's margin) swing into the shelf one way round and into the table the other;
    beyond their ends there is room."""
    occ = np.zeros((120, 160), dtype=bool)
    origin = (-4.0, -3.0)
    xs = origin[0] + (np.arange(160) + 0.5) * RES
    ys = origin[1] + (np.arange(120) + 0.5) * RES
    occ[np.ix_((ys >= -1.0) & (ys <= 0.0), (xs >= -1.5) & (xs <= 0.8))] = True
    occ[np.ix_(ys >= 1.25, (xs >= -1.5) & (xs <= 1.0))] = True
    return Grid(occ, RES, origin), Pose(3.0, 0.57, math.pi), Pose(0.0, 0.57, -math.pi / 2)


def test_a_goal_with_no_room_to_turn_is_turned_to_where_the_path_has_room() -> None:
    """Hall seed 4's shift: the path came along a table to the standoff, the turn there
    was refused either way round, and the robot stood 20 s aligning 2.1 rad off. The turn
    is done where the body has room (`turn_point`), and it walks the rest sideways."""
    from services.navigation.body_guard import turn_point

    grid, start, goal = _table_scene()
    cm = build_costmap(grid, FP, CostParams())
    xs = np.linspace(start.x, goal.x, 61)
    path = np.column_stack([xs, np.full_like(xs, goal.y), np.full_like(xs, math.pi)])
    path[-1, 2] = goal.yaw
    j = turn_point(cm.solid, grid, FP, path)
    assert 1.0 < path[j, 0] <= 1.3  # just past the shelf's end: the nearest with room
    open_floor = build_costmap(Grid(np.zeros_like(grid.occupied), RES, grid.origin), FP,
                               CostParams())  # fmt: skip
    assert turn_point(open_floor.solid, grid, FP, path) == len(path) - 1  # room at the goal
    nav = Navigator(FP, NavigationSettings(), DT)
    nav.start(GoalSpec("g", goal, 0.1, 0.1), 0)
    pose, cmd, said = start, np.zeros(3), set()
    turned_at = None
    for k in range(1200):
        pose = _step(pose, cmd)
        out = nav.tick(int(k * DT * 1e9), pose, cm)
        cmd = out.cmd
        said.add(out.detail)
        assert footprint_free(cm.solid, grid, pose, FP, 0.0), (k, pose)
        if turned_at is None and abs(math.remainder(pose.yaw - goal.yaw, math.tau)) < 0.2:
            turned_at = pose.x
        if out.state != "active":
            break
    assert out.state == "succeeded", out
    assert any("turned to the goal's heading" in d for d in said), said
    assert turned_at is not None and turned_at > 1.2  # turned before the table's end
