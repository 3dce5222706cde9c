"""Navigation's protective field: people the lidar sees where the map knows nothing.

Scans are ray-cast here against circles (a person's legs at the lidar's height, 0.07 m
radius, 0.2 m apart) and the map's own walls, from the lidar's mount on the base.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from common import robot
from common.scan import scan_points
from services.navigation.costmap import CostParams, Person
from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint
from services.navigation.nav_map import AHEAD_MAX_S, NavMap, ahead
from services.navigation.scan_people import (
    ScanParams,
    ScanPeople,
    ScanView,
    VelocityMemory,
    bodies,
    bodies_and_larger,
    merge_scan,
    nearest_tracks,
    static_cells,
)

S = 1_000_000_000
RES = 0.05
ANGLES = np.linspace(-math.radians(135), math.radians(135), 541)
T_BASE_LIDAR = robot.LIDAR_MOUNT.T_parent_lidar
FP = Footprint.stowed()


def _room(unknown: list[tuple[slice, slice]] | None = None) -> Grid:
    """A 12 m square room centred on the origin, walls one cell thick; `unknown`: blocks
    of cells (iy, ix slices) the map has not seen."""
    n = round(12.0 / RES)
    occ = np.zeros((n, n), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    solid = occ.copy()
    for block in unknown or []:
        occ[block] = True
    return Grid(occ, RES, (-6.0, -6.0), solid)


def _scan(pose: Pose, legs: list[tuple[float, float]], room_half: float = 5.95) -> np.ndarray:
    """The ranges from the lidar on the base at `pose`: circles of 0.07 m at `legs`, the
    room's walls at ±`room_half` (their inner faces)."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    ox = pose.x + c * T_BASE_LIDAR[0, 3] - s * T_BASE_LIDAR[1, 3]
    oy = pose.y + s * T_BASE_LIDAR[0, 3] + c * T_BASE_LIDAR[1, 3]
    a = ANGLES + pose.yaw
    dx, dy = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (room_half - ox) / dx, (-room_half - ox) / dx)
        ty = np.where(dy > 0, (room_half - oy) / dy, (-room_half - oy) / dy)
    r = np.minimum(tx, ty)
    for lx, ly in legs:
        fx, fy = ox - lx, oy - ly
        b = fx * dx + fy * dy
        disc = b * b - (fx * fx + fy * fy - 0.07**2)
        t = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        r = np.where((t > 0) & (t < r), t, r)
    return r


def _points(pose: Pose, legs: list[tuple[float, float]]) -> np.ndarray:
    """The scan as points in the map frame (what the node gives `ScanPeople`)."""
    base = scan_points(_scan(pose, legs), float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]),
                       T_BASE_LIDAR)  # fmt: skip
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return base @ np.array([[c, s], [-s, c]]) + np.array([pose.x, pose.y])


def _person(x: float, y: float) -> list[tuple[float, float]]:
    return [(x, y + 0.1), (x, y - 0.1)]


def test_a_person_standing_beside_the_robot_is_one_body_and_the_walls_none() -> None:
    tracker = ScanPeople(FP)
    pose = Pose(0.0, 0.0, 0.0)
    tracker.update(_points(pose, _person(0.2, 1.2)), _room(), pose, 0)
    assert len(tracker.bodies) == 1
    b = tracker.bodies[0]
    # The near side of the legs: a little towards the robot from the person's centre.
    assert b.x == pytest.approx(0.2, abs=0.1) and 1.05 < b.y < 1.2
    assert b.extent_m < 0.5
    (p,) = tracker.people(0)
    assert p.id == "scan_1" and p.velocity is None  # not known yet: a walking pace assumed


def test_bodies_left_out_where_the_map_knows_the_world() -> None:
    pose = Pose(0.0, 0.0, 0.0)
    # Legs against the wall (within the margin), and legs in a large unknown area.
    legs = _person(5.85, 0.0) + _person(-2.0, 3.0)
    unknown = [(slice(160, 240), slice(50, 110))]  # 3 m × 4 m round (-2, 3): unexplored
    tracker = ScanPeople(FP)
    tracker.update(_points(pose, legs), _room(unknown), pose, 0)
    assert tracker.bodies == []
    # The same area as a small island of unknown (a body's shadow in the map): floor.
    island = [(slice(177, 183), slice(77, 83))]  # 0.3 m × 0.3 m at (-2, 3)
    tracker = ScanPeople(FP)
    tracker.update(_points(pose, _person(-2.0, 3.0)), _room(island), pose, 0)
    assert len(tracker.bodies) == 1


def test_static_cells_keep_the_unexplored_and_drop_small_islands() -> None:
    grid = _room([(slice(10, 110), slice(10, 110)), (slice(150, 154), slice(150, 154))])
    st = static_cells(grid, island_m2=1.0)
    assert st[50, 50] and not st[151, 151] and st[0, 5]


def test_the_clusters_of_a_wall_a_few_returns_and_two_legs() -> None:
    p = ScanParams()
    wall = np.column_stack([np.full(40, 2.0), np.linspace(-1.0, 1.0, 40)])
    stray = np.array([[3.0, 3.0], [3.01, 3.0]])
    legs = np.array([[1.0, 0.1], [1.0, 0.12], [1.0, 0.14], [1.0, -0.1], [1.0, -0.12], [1.0, -0.14]])
    out = bodies(np.vstack([wall, stray, legs]), p)
    assert len(out) == 1 and out[0].points == 6 and out[0].x == pytest.approx(1.0)


def test_a_flat_face_as_wide_as_a_person_is_no_body_and_legs_are_one() -> None:
    """Hall seed 0's shift: a trolley left in an aisle showed its 0.6 m end square on, a
    person-sized cluster; as a new track it was a walker to the speed rules, and the robot
    stood 170 s before it. Its returns are a straight line; legs are two arcs, at most
    0.34 m across whichever way they face."""
    p = ScanParams()
    rng = np.random.default_rng(1)
    end = np.column_stack([np.full(60, 2.0), np.linspace(-0.3, 0.3, 60)])
    end[:, 0] += rng.normal(0.0, 0.015, 60)  # the range noise
    found, larger = bodies_and_larger(end, p)
    assert found == [] and len(larger) == 60
    assert bodies_and_larger(end[::3], dataclasses.replace(p, max_face_m=1.0))[0]  # as was
    for turn in np.linspace(0.0, math.pi, 7):  # legs facing every way, 0.8-4.5 m off
        for d in (0.8, 2.0, 4.5):
            legs = [(d + 0.1 * math.sin(turn) * k, 0.1 * math.cos(turn) * k) for k in (1, -1)]
            pts = _points(Pose(0.0, 0.0, 0.0), legs)
            near = pts[np.hypot(pts[:, 0] - d, pts[:, 1]) < 0.5]
            assert len(bodies(near, p)) == 1, (turn, d)


def test_a_walking_person_keeps_one_track_with_their_velocity() -> None:
    tracker = ScanPeople(FP)
    pose = Pose(0.0, 0.0, 0.0)
    grid = _room()
    for k in range(8):  # 1 m/s along −y, 2 m to the robot's left and ahead, 10 Hz
        t = k * S // 10
        tracker.update(_points(pose, _person(2.0, 3.0 - 0.1 * k)), grid, pose, t)
    (p,) = tracker.people(7 * S // 10)
    assert p.id == "scan_1"
    assert p.velocity is not None
    assert p.velocity[0] == pytest.approx(0.0, abs=0.1)
    assert p.velocity[1] == pytest.approx(-1.0, abs=0.1)
    # Out of the field: the track ends after its time to live.
    tracker.update(_points(pose, []), grid, pose, 8 * S // 10)
    assert tracker.people(8 * S // 10)
    tracker.update(_points(pose, []), grid, pose, 14 * S // 10)
    assert tracker.people(14 * S // 10) == []


def test_two_people_crossing_keep_their_ids() -> None:
    tracker = ScanPeople(FP)
    pose = Pose(0.0, 0.0, 0.0)
    grid = _room()
    first: dict[str, float] = {}
    for k in range(12):  # 1 m/s each way, passing 0.4 m apart at k = 10
        t = k * S // 10
        legs = _person(2.0 + 0.1 * k, 2.2) + _person(4.0 - 0.1 * k, 1.8)
        tracker.update(_points(pose, legs), grid, pose, t)
        if k == 0:
            first = {p.id: p.y for p in tracker.people(t)}
    people = tracker.people(11 * S // 10)
    assert len(people) == 2 and {p.id for p in people} == set(first)
    for p in people:  # each on their own line, still, at their own speed
        assert p.y == pytest.approx(first[p.id], abs=0.15)  # the near side of the legs
        assert p.velocity is not None
        assert abs(p.velocity[0]) == pytest.approx(1.0, abs=0.15)
        assert (p.velocity[0] > 0) == (first[p.id] > 2.0)


def test_what_the_robot_carries_is_not_a_person() -> None:
    tracker = ScanPeople(FP)
    pose = Pose(1.0, 0.0, 0.0)
    # A small object just off the footprint's front face (the arm's load): within the margin.
    held = [(1.0 + FP.front + 0.09, 0.0)]
    tracker.update(_points(pose, held), _room(), pose, 0)
    assert tracker.bodies == []


def test_merge_puts_a_track_on_the_person_it_is_and_adds_the_rest() -> None:
    known = [Person("person_2", 3.0, 1.0, velocity=(0.0, 0.0)), Person("person_1", -4.0, 0.0)]
    scanned = [
        Person("scan_4", 3.2, 0.9, velocity=(0.5, 0.0)),
        Person("scan_5", 0.0, 2.0, velocity=None),
    ]
    out = merge_scan(known, scanned, same_m=0.6)
    assert [(p.id, p.x, p.y, p.velocity) for p in out] == [
        ("person_2", 3.2, 0.9, (0.5, 0.0)),
        ("person_1", -4.0, 0.0, (0.0, 0.0)),
        ("scan_5", 0.0, 2.0, None),
    ]
    # a track with no velocity yet: the person's own if it is a motion, else unknown
    fresh = [Person("scan_6", 3.1, 1.0, velocity=None), Person("scan_7", -4.1, 0.0, velocity=None)]
    walking = [Person("person_2", 3.0, 1.0, velocity=(0.0, 0.0)),
               Person("person_1", -4.0, 0.0, velocity=(1.0, 0.0))]  # fmt: skip
    assert [p.velocity for p in merge_scan(walking, fresh, same_m=0.6)] == [None, (1.0, 0.0)]


def test_a_new_track_of_a_person_keeps_the_velocity_the_lidar_measured_for_them_lately() -> None:
    """The handover's person, standing, a new track every second or two (the changing
    hall's shift): a new track's unknown velocity would be a walking pace, a stop."""
    memory = VelocityMemory(hold_s=1.0)
    person = [Person("person_1", 1.0, 0.0, velocity=(0.0, 0.0))]  # the map's: no evidence
    measured = [Person("scan_3", 1.05, 0.0, velocity=(0.02, -0.01))]
    assert merge_scan(person, measured, 0.6, memory, 0)[0].velocity == (0.02, -0.01)
    again = [Person("scan_9", 1.1, 0.0, velocity=None)]  # the track broke up: a new one
    assert merge_scan(person, again, 0.6, memory, 400_000_000)[0].velocity == (0.02, -0.01)
    assert merge_scan(person, again, 0.6, memory, 1_100_000_000)[0].velocity is None  # too old
    other = [Person("person_2", 1.0, 0.0, velocity=(0.0, 0.0))]  # not theirs to keep
    assert merge_scan(other, again, 0.6, memory, 400_000_000)[0].velocity is None
    assert merge_scan(person, again, 0.6)[0].velocity is None  # no memory: unknown


def test_the_nav_map_rebuilds_for_a_person_come_or_moved_not_for_jitter() -> None:
    import logging

    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    grid = _room()
    m.adopt(grid, [], 0, 0)
    pose = Pose(0.0, 0.0, 0.0)
    assert m.see_scan(_points(pose, _person(2.0, 2.0)), pose, 0)  # came: rebuild
    m.rebuild(0)
    built = m.costmap
    assert built is not None and [p.id for p in built.people] == ["scan_1"]
    assert not m.see_scan(_points(pose, _person(2.02, 2.0)), pose, S // 10)  # 2 cm
    assert m.costmap is not None and m.costmap.cost is built.cost  # same costs …
    assert m.costmap.people[0].x > built.people[0].x  # … the newest position
    assert m.see_scan(_points(pose, _person(2.2, 2.0)), pose, 2 * S // 10)  # 0.2 m: rebuild


def _view(pose: Pose, legs: list[tuple[float, float]]) -> ScanView:
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    origin = (pose.x + c * T_BASE_LIDAR[0, 3], pose.y + s * T_BASE_LIDAR[0, 3])
    step = float(ANGLES[1] - ANGLES[0])
    return ScanView(origin, pose.yaw, float(ANGLES[0]), step, _scan(pose, legs), 10.0)


def test_the_scan_says_where_nobody_stands_and_not_where_it_cannot_see() -> None:
    pose = Pose(0.0, 0.0, 0.0)
    view = _view(pose, _person(2.0, 1.0))
    assert not view.clear_at(2.0, 1.0)  # their legs stop the beams
    assert not view.clear_at(2.1, 1.2)  # the map's estimate a little off: still them
    assert not view.clear_at(2.0, 1.45)  # 0.35 m off their legs (the shift's standing ones)
    assert view.clear_at(2.0, -1.5)  # the beams go on to the wall
    assert not view.clear_at(-2.0, 0.0)  # behind the lidar: out of its field
    assert not view.clear_at(3.0, 1.5)  # in the legs' shadow: the scan cannot say


def test_the_nav_map_leaves_out_people_the_lidar_sees_gone_or_inside_the_robot() -> None:
    import logging

    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    pose = Pose(0.0, 0.0, 0.0)
    mapped = [
        Person("person_1", 2.0, -1.5),  # walked off: the floor there is seen free
        Person("person_2", 2.0, 1.0),  # still there
        Person("person_3", 0.1, 0.0),  # the tracker carried them into the robot
    ]
    m.adopt(_room(), mapped, 0, 0)
    m.see_scan(_points(pose, _person(2.0, 1.0)), pose, 0, [_view(pose, _person(2.0, 1.0))])
    assert [q.id for q in m.people] == ["person_2"]
    assert m.left_out == {
        "person_1": "the lidar sees free floor there",
        "person_3": "inside the robot's footprint",
    }


def test_a_map_person_whose_place_the_lidar_saw_free_stays_out_once_it_cannot_see_there() -> None:
    """Hall seed 0's shift: a ghost the map kept 0.76 m off the robot's flank, in the blind
    wedge beside the trunk, held its goal under the stop rule. The lidar saw that place
    free before the robot turned: until the map sees them again (or has them elsewhere),
    they stay out of the layer."""
    import logging

    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    ghost = Person("person_1", 2.0, -1.5, seen_ns=0)  # last seen there at 0 s
    m.adopt(_room(), [ghost], 0, 0)
    front = Pose(0.0, 0.0, 0.0)
    m.see_scan(_points(front, []), front, S, [_view(front, [])])
    assert m.people == []  # seen free at 1 s
    turned = Pose(0.0, 0.0, math.pi)  # the place behind the front lidar now
    assert not _view(turned, []).clear_at(2.0, -1.5)
    m.see_scan(_points(turned, []), turned, 2 * S, [_view(turned, [])])
    assert m.people == []
    assert m.left_out["person_1"] == "the lidar sees free floor there"  # said once
    for back in (
        dataclasses.replace(ghost, seen_ns=3 * S),  # the map saw them there again
        dataclasses.replace(ghost, x=2.0, y=-2.2),  # the map has them elsewhere now
        dataclasses.replace(ghost, seen_ns=None),  # seen now (a camera's, a scan track's)
    ):
        m.adopt(_room(), [back], 3 * S, 3 * S)
        assert [q.id for q in m.people] == ["person_1"], back


def _without(view: ScanView, lost: np.ndarray) -> ScanView:
    """`view` with the beams `lost` (a mask) returning nothing."""
    return dataclasses.replace(view, ranges=np.where(lost, 0.0, view.ranges))


def test_beams_without_a_return_say_nothing_where_the_robot_masks_them() -> None:
    """Beyond ±90° of the heading the robot's legs meet the beams (masked: no return):
    there no return is no free floor. A scan with hardly any returns says nothing."""
    pose = Pose(0.0, 0.0, 0.0)
    view = _view(pose, [])
    angles = ANGLES
    assert view.clear_at(0.8, 0.9)  # ahead-left, its cone reaching past 90°
    assert not _without(view, np.abs(angles) > math.radians(90.0)).clear_at(0.8, 0.9)
    assert not _without(view, np.ones(len(angles), dtype=bool)).clear_at(2.0, -1.5)
    assert not _without(view, np.arange(len(angles)) % 20 != 0).clear_at(2.0, -1.5)


def test_beams_without_a_return_in_the_open_field_see_free_floor() -> None:
    """Hall seed 2's shift: the map kept a worker who had walked on 0.7 m off the lidar;
    in a hall most beams return nothing within the range (a wall 15 m away), and the
    robot stood 100 s by the empty place. No return within ±90° is free floor; a beam
    that returns short of the place is not."""
    pose = Pose(0.0, 0.0, 0.0)
    view = _view(pose, [])
    open_hall = _without(view, np.abs(ANGLES) < math.radians(20.0))  # a far wall ahead
    assert open_hall.clear_at(1.0, 0.4)
    person = _view(pose, _person(1.0, 0.4))
    assert not _without(person, (np.abs(ANGLES) < math.radians(20.0)) & (person.ranges > 2.0)
                        ).clear_at(1.0, 0.4)  # fmt: skip


def test_the_rear_lidar_says_who_is_gone_behind_the_robot_where_the_front_one_cannot() -> None:
    import logging

    pose = Pose(0.0, 0.0, 0.0)
    # The rear lidar (0.46 m behind the base, facing back) sees what the front one would
    # from the base turned round.
    rear = _view(Pose(0.0, 0.0, math.pi), [])
    front = _view(pose, [])
    assert rear.origin[0] == pytest.approx(-T_BASE_LIDAR[0, 3])
    assert not front.clear_at(-2.0, 0.5) and rear.clear_at(-2.0, 0.5)
    for views, kept in (([front], ["person_4"]), ([front, rear], [])):
        m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
        m.adopt(_room(), [Person("person_4", -2.0, 0.5)], 0, 0)  # walked off behind it
        m.see_scan(_points(pose, []), pose, 0, views)
        assert [q.id for q in m.people] == kept


def _trolley(x: float, y: float, length: float = 1.0) -> list[tuple[float, float]]:
    """A trolley's long side along x at y, in the lidar's plane: circles 0.1 m apart
    (their returns as close together as a flat face's)."""
    n = round(length / 0.1) + 1
    return [(x - 0.5 * length + 0.1 * k, y) for k in range(n)]


def test_a_trolley_the_map_lacks_is_no_person_but_an_obstacle_marked_in_the_layer() -> None:
    """Larger than a person (1 m across): no body, no track; its returns are marked in the
    short-lived layer at the scan's stamp (the lidar sees it where the head camera does
    not look: beside the robot here) and the costmap is rebuilt round it."""
    import logging

    pose = Pose(0.0, 0.0, 0.0)
    pts = _points(pose, _trolley(0.0, -2.0))
    field = ScanPeople(FP)
    field.update(pts, _room(), pose, 0)
    assert field.bodies == [] and field.people(0) == []
    assert len(field.obstacles) >= 10
    assert np.all(np.abs(field.obstacles[:, 1] + 2.0) < 0.1)
    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    m.adopt(_room(), [], 0, 0)
    views = [_view(pose, _trolley(0.0, -2.0))]
    assert m.see_scan(pts, pose, S, views)  # marked: rebuild
    m.rebuild(S)
    cell = m.grid.cell(0.0, -1.93) if m.grid is not None else None  # its near face
    assert cell is not None and m.scan_layer.active(S)[cell]
    assert m.costmap is not None and m.costmap.cost[cell] < 0  # lethal where it stands
    m.see_scan(pts, pose, 2 * S, views)  # seen again: its beams stop at it, none clears it
    assert np.array_equal(m.scan_layer.active(2 * S), m.scan_layer.active(S))
    # Kept while the robot is away (the depth layer's 3 s would have let it go) …
    assert m.scan_layer.active(60 * S)[cell]
    # … until the lidar's beams pass where it stood: taken away.
    assert m.see_scan(_points(pose, []), pose, 61 * S, [_view(pose, [])])
    assert not m.scan_layer.active(61 * S)[cell]
    # A person's legs are a body, not an obstacle.
    field.update(_points(pose, _person(0.0, -2.0)), _room(), pose, 2 * S)
    assert len(field.bodies) == 1 and len(field.obstacles) == 0


def test_a_beam_passes_a_point_when_it_returns_beyond_it_or_returns_nothing_in_range() -> None:
    pose = Pose(0.0, 0.0, 0.0)
    wall = _view(pose, [])  # the room's walls at 5.95 m
    pts = np.array([[2.0, 0.5], [5.9, 0.5], [-3.0, 0.5]])  # off the beam at 0 rad (its /0)
    assert wall.through(pts).tolist() == [True, False, False]  # at the wall; behind: no beam
    empty = ScanView(wall.origin, 0.0, wall.angle_min, wall.angle_increment,
                     np.zeros_like(wall.ranges), 10.0)  # fmt: skip
    assert empty.through(np.array([[2.0, 0.0], [11.0, 0.0]])).tolist() == [True, False]


def _masked(pose: Pose, legs: list[tuple[float, float]]) -> tuple[np.ndarray, ScanView]:
    """The front lidar's scan as the trunk masks it (no return beyond ±97°: the sim's
    B1), as points and rays."""
    view = _view(pose, legs)
    ranges = np.where(np.abs(ANGLES) > math.radians(97.0), 0.0, view.ranges)
    view = ScanView(view.origin, view.heading, view.angle_min, view.angle_increment,
                    ranges, view.range_max)  # fmt: skip
    base = scan_points(ranges, float(ANGLES[0]), view.angle_increment, T_BASE_LIDAR)
    return base + np.array([pose.x, pose.y]), view  # the robot at yaw 0


def test_a_person_walking_into_the_blind_wedge_beside_the_trunk_coasts_along_their_velocity() -> (
    None
):
    """Walking at 1 m/s along −x, 1.2 m to the robot's right: seen ahead, then beside the
    trunk where the masked beams say nothing. The track lives on past `ttl_s` where its
    velocity takes them, for the monitor."""
    tracker = ScanPeople(FP)
    pose, grid = Pose(0.0, 0.0, 0.0), _room()
    seen_to = 0
    for k in range(31):  # 3 s at 10 Hz, from x = 2.0 to x = −1.0
        t, x = k * S // 10, 2.0 - 0.1 * k
        pts, view = _masked(pose, _person(x, -1.2))
        tracker.update(pts, grid, pose, t, [view])
        if tracker.bodies:
            seen_to = k
        if k == 22:  # x = -0.2: beside the trunk, unseen for a second
            (p,) = tracker.people(t)
            assert p.id == "scan_1" and p.velocity is not None
            assert p.velocity[0] == pytest.approx(-1.0, abs=0.15)
            assert p.x == pytest.approx(x, abs=0.2) and p.y == pytest.approx(-1.2, abs=0.2)
    assert 10 < seen_to < 22  # lost in the wedge (the front lidar sees down to ±97°)
    # Without the rays (no beam can say), a track ends at its time to live as before.
    bare = ScanPeople(FP)
    for k in range(seen_to + 7):
        pts, _ = _masked(pose, _person(2.0 - 0.1 * k, -1.2))
        bare.update(pts, grid, pose, k * S // 10)
    assert bare.people((seen_to + 6) * S // 10) == []


def test_a_coasting_track_ends_once_a_beam_passes_where_it_would_be() -> None:
    """A person standing ahead who is gone (the beams reach the wall behind them) ends at
    the time to live; one the trunk masks coasts (at rest, where they were) up to
    `coast_s`."""
    pose, grid = Pose(0.0, 0.0, 0.0), _room()
    tracker = ScanPeople(FP)
    pts, view = _masked(pose, _person(2.0, 0.5))
    tracker.update(pts, grid, pose, 0, [view])
    for k in range(1, 8):
        pts, view = _masked(pose, [])
        tracker.update(pts, grid, pose, k * S // 10, [view])
    assert tracker.people(7 * S // 10) == []  # the beams go through: gone
    beside = ScanPeople(FP)
    pts, view = _masked(pose, _person(0.4, -1.2))  # just inside the front lidar's field
    beside.update(pts, grid, pose, 0, [view])
    assert beside.bodies
    for k in range(1, 35):
        pts, view = _masked(pose, [])
        # The masked beams towards (0.4, −1.2) read nothing: it cannot be said gone.
        view = ScanView(view.origin, view.heading, view.angle_min, view.angle_increment,
                        np.where(np.abs(ANGLES + math.radians(95.0)) < 0.1, 0.0, view.ranges),
                        view.range_max)  # fmt: skip
        beside.update(pts, grid, pose, k * S // 10, [view])
        alive = beside.people(k * S // 10)
        assert bool(alive) == (k <= 30), k  # coast_s = 3 s


def test_a_person_standing_where_no_lidar_looks_coasts_longer_than_one_in_the_open_field() -> None:
    """Hall seed 4's shift (t = 423.8 s): a worker stood 3.3 s in the wedge beside the
    trunk, their track ended at `coast_s`, and the robot walked towards them when they
    moved. A track standing (a measured velocity at rest) where no lidar's open field
    reaches coasts `blind_hold_s`; one standing in the open field, its beams reading
    nothing now, still ends at `coast_s`."""
    pose, grid = Pose(0.0, 0.0, 0.0), _room()

    def alive_until(x: float, y: float) -> int:
        tracker = ScanPeople(FP)
        for k in range(6):  # 0.5 s in view, at rest
            pts, view = _masked(pose, _person(x, y))
            tracker.update(pts, grid, pose, k * S // 10, [view])
        (q,) = tracker.people(5 * S // 10)
        assert q.velocity is not None and math.hypot(*q.velocity) < 0.05
        origin = np.array(_view(pose, []).origin)
        toward = math.atan2(y - origin[1], x - origin[0])
        last = 5
        for k in range(6, 130):
            pts, view = _masked(pose, [])
            view = ScanView(view.origin, view.heading, view.angle_min, view.angle_increment,
                            np.where(np.abs(ANGLES - toward) < 0.1, 0.0, view.ranges),
                            view.range_max)  # fmt: skip
            tracker.update(pts, grid, pose, k * S // 10, [view])
            if tracker.people(k * S // 10):
                last = k
        return last

    assert alive_until(0.4, -1.2) == 5 + 100  # beside the trunk: 10 s unseen
    assert alive_until(2.0, 0.5) == 5 + 30  # ahead, where a beam could see them: 3 s


def test_a_walker_the_map_saw_lately_is_carried_along_their_velocity_to_the_tick() -> None:
    """The map's place of a walker is its newest frame's, late: the speed rules take them
    where their velocity has carried them since (for at most `AHEAD_MAX_S`); a standing
    person, or one seen by a sensor now (no `seen_ns`), is where they are."""
    import logging

    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    walker = Person("person_1", 2.0, 2.0, velocity=(1.0, 0.0), seen_ns=S)
    stander = Person("person_2", -2.0, 2.0, velocity=(0.0, 0.0), seen_ns=0)
    m.adopt(_room(), [walker, stander], S, S + S // 2)
    assert m.costmap is not None
    where = {p.id: (round(p.x, 3), round(p.y, 3)) for p in m.costmap.people}
    assert where == {"person_1": (2.5, 2.0), "person_2": (-2.0, 2.0)}
    assert ahead(walker, 5 * S).x == 2.0 + AHEAD_MAX_S  # no further than that
    now = dataclasses.replace(walker, seen_ns=None)
    assert ahead(now, 5 * S) == now


def test_the_tracks_said_are_the_nearest_within_range() -> None:
    """`nav/status` says the lidar's tracks near the base, nearest first, a bounded few."""
    tracks = [Person(f"scan_{k}", float(k), 0.0, None, None) for k in (5, 1, 9, 3)]
    assert [q.id for q in nearest_tracks(tracks, 0.0, 0.0, within_m=6.0)] == [
        "scan_1", "scan_3", "scan_5"]  # fmt: skip
    assert [q.id for q in nearest_tracks(tracks, 0.0, 0.0, within_m=6.0, most=2)] == [
        "scan_1", "scan_3"]  # fmt: skip
    assert nearest_tracks([], 0.0, 0.0) == []


def test_a_person_near_the_robot_lost_by_every_sensor_is_held_a_moment() -> None:
    """Hall seed 3's shift: the lidar's track of a worker standing 0.6 m off the footprint
    ended, and for 0.8 s the layer had nobody; the robot walked on towards them. A person
    the layer had within `NEAR_HOLD_M` stays where it last had them for `NEAR_HOLD_S`, then
    goes; one lost farther off goes at once; one found again beside where they were is
    not held as well."""
    import logging

    from services.navigation.nav_map import NEAR_HOLD_M, NEAR_HOLD_S

    pose = Pose(0.0, 0.0, 0.0)

    def scan(m: NavMap, t_ns: int, legs: list[tuple[float, float]]) -> list[tuple[str, float]]:
        pts, view = _masked(pose, legs)
        m.see_scan(pts, pose, t_ns, [view])
        return [(p.id, p.x) for p in m.people]

    lost = 8 * S // 10  # past the track's time to live, every beam through their place
    after = 2 * S // 10 + round(NEAR_HOLD_S * S) + S // 10
    for x, held in ((1.2, True), (FP.front + NEAR_HOLD_M + 0.4, False)):
        m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
        m.adopt(_room(), [], 0, 0)
        for k in range(3):  # tracked at 10 Hz
            seen = scan(m, k * S // 10, _person(x, 0.3))
        assert len(seen) == 1 and seen[0][1] == pytest.approx(x, abs=0.15)
        assert scan(m, lost, []) == (seen if held else []), x
        assert scan(m, after, []) == []
    m = NavMap(FP, CostParams(), S, True, "test", logging.getLogger("test"))
    m.adopt(_room(), [], 0, 0)
    for k in range(3):
        scan(m, k * S // 10, _person(1.2, 0.3))
    assert len(scan(m, lost, _person(1.2, 0.7))) == 1  # a new track of them: theirs alone


def test_a_walker_turning_in_where_no_lidar_looks_is_taken_at_the_nearest_place_they_could_be() -> (
    None
):
    """Hall seed 4's shift (t = 536.8 s): a worker walking at 1 m/s turned in beside the
    trunk to stand by the robot; their track coasted on along the old velocity, past the
    robot, and the stop for them was released. Walking along −x 1.2 m to the robot's
    right, they turn in where the trunk masks the beams and stand 0.4 m off its flank:
    while unseen, the track is never farther from the footprint than they are, with the
    velocity they had; when they walk out into the field they are the same track. A
    walker who is gone where every beam sees (the room's far wall behind them) ends."""
    pose, grid = Pose(0.0, 0.0, 0.0), _room()
    tracker = ScanPeople(FP)
    path = [(2.0 - 0.1 * k, -1.2) for k in range(21)]  # to x = 0 along −x
    path += [(0.0, -1.2 + 0.1 * k) for k in range(1, 6)]  # turn in, to 0.7 m off the axis
    path += [(0.0, -0.7)] * 13
    path += [(0.1 * k, -0.7) for k in range(1, 11)]  # then forward, into the field
    unseen = checked = 0
    for k, (x, y) in enumerate(path):
        t = k * S // 10
        pts, view = _masked(pose, _person(x, y))
        tracker.update(pts, grid, pose, t, [view])
        unseen = 0 if tracker.bodies else unseen + 1
        people = tracker.people(t)
        assert [q.id for q in people] == ["scan_1"], k  # one track, never lost nor doubled
        (q,) = people
        if unseen > 5:  # past its time to live
            d_track, d_true = distance_to_footprint(pose, FP, np.array([[q.x, q.y], [x, y]]))
            assert d_track <= d_true, (k, q)
            assert q.velocity is not None and q.velocity[0] < -0.5  # the pace they had
            checked += 1
    assert unseen == 0 and checked >= 15  # unseen 2 s and more, then found in the field
    # Walking ahead in the open and gone: every place within their reach is seen free.
    gone = ScanPeople(FP)
    for k in range(20):
        t = k * S // 10
        legs = _person(2.5, 1.0 - 0.1 * k) if k < 8 else []
        pts, view = _masked(pose, legs)
        gone.update(pts, grid, pose, t, [view])
        if k >= 8 + 6:
            assert gone.people(t) == [], k
