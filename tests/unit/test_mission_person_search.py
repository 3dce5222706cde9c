"""The usual place of a person looked at next: usual, not looked at yet, the nearest;
the body looked at while the robot asks: near, unseen, unnamed, the nearest."""

from __future__ import annotations

import math

import msgspec
import pytest

from common.messages.navigation import ScanBody
from common.messages.semantic_map import SeenPlace
from services.mission.person_search import GLANCE_M, LEAD_S, glance_at, next_place
from tests.unit.mission_fakes import entity

S = 1_000_000_000


def _p(x: float, y: float, n: int) -> SeenPlace:
    return SeenPlace(xy=(x, y), sightings=n, last_seen_ns=n * S)


def test_the_nearest_usual_place_not_looked_at_is_next() -> None:
    places = [_p(10.0, 0.0, 8), _p(4.0, 0.0, 6), _p(2.0, 0.0, 5)]
    assert next_place(places, [], (-2.0, 0.0)) == places[2]
    assert next_place(places, [(1.5, 0.5)], (-2.0, 0.0)) == places[1]
    assert next_place(places, [(1.5, 0.5), (4.5, 1.0)], (-2.0, 0.0)) == places[0]
    assert next_place(places, [(1.5, 0.5), (4.5, 1.0), (9.0, 0.0)], (-2.0, 0.0)) is None


def test_a_place_passed_once_is_not_a_usual_place() -> None:
    bench, passed = _p(8.0, 3.0, 40), _p(1.0, 0.0, 2)
    assert next_place([bench, passed], [], (0.0, 0.0)) == bench


def test_where_the_robot_stands_is_looked_at_already() -> None:
    here, there = _p(0.5, 0.5, 4), _p(6.0, 0.0, 4)
    assert next_place([here, there], [], (0.0, 0.0)) == there


def test_no_places_or_no_pose() -> None:
    assert next_place([], [], (0.0, 0.0)) is None
    places = [_p(3.0, 0.0, 9), _p(1.0, 0.0, 4)]
    assert next_place(places, [], None) == places[0]  # the most seen first


def test_the_body_looked_at_is_the_nearest_out_of_view_and_unnamed() -> None:
    """The robot at the origin facing +x: a body ahead is in the camera's view, one past
    `GLANCE_M` too far; of the two behind, the nearer is turned to, aimed where its
    velocity takes it in `LEAD_S`."""
    bodies = [
        ScanBody(id="scan_1", x=2.0, y=0.2),  # ahead: in view
        ScanBody(id="scan_2", x=-3.0, y=-1.0, velocity=(0.0, 1.0)),
        ScanBody(id="scan_3", x=0.0, y=-GLANCE_M - 0.2),  # too far
        ScanBody(id="scan_4", x=-1.0, y=-4.0),
    ]
    got = glance_at(bodies, [], (0.0, 0.0), 0.0, 10 * S)
    assert got is not None
    body, aim = got
    assert body.id == "scan_2"
    assert aim == pytest.approx(math.atan2(-1.0 + LEAD_S, -3.0))
    again = glance_at(bodies, [], (0.0, 0.0), 0.0, 10 * S, glanced={"scan_2": (-3.0, -1.0)})
    assert again is not None and again[0].id == "scan_4"  # each track once
    both = {"scan_2": (-3.0, -1.0), "scan_4": (-1.0, -4.0)}
    assert glance_at(bodies, [], (0.0, 0.0), 0.0, 10 * S, glanced=both) is None


def test_a_body_looked_at_once_is_looked_at_again_once_it_came_to_stand_near() -> None:
    """Seed 0's shift: person_4, looked at 4.4 m off and not named, heard the ask, came
    and stood 1.3 m behind the robot: looked at again. A walker who only walked on is
    not, nor one who stands where they were looked at."""
    was = {"scan_46": (-4.0, -1.5)}
    came = ScanBody(id="scan_46", x=-1.3, y=0.1, velocity=(0.0, 0.05))
    got = glance_at([came], [], (0.0, 0.0), 0.0, 10 * S, glanced=was)
    assert got is not None and got[0].id == "scan_46"
    walking = ScanBody(id="scan_46", x=-1.3, y=0.1, velocity=(1.0, 0.0))
    assert glance_at([walking], [], (0.0, 0.0), 0.0, 10 * S, glanced=was) is None
    far = ScanBody(id="scan_46", x=-3.0, y=0.1, velocity=(0.0, 0.0))  # beyond ANSWER_M
    assert glance_at([far], [], (0.0, 0.0), 0.0, 10 * S, glanced=was) is None
    stayed = ScanBody(id="scan_46", x=-1.3, y=0.1, velocity=(0.0, 0.0))
    assert glance_at([stayed], [], (0.0, 0.0), 0.0, 10 * S,
                     glanced={"scan_46": (-1.5, 0.3)}) is None  # fmt: skip


def test_a_body_the_camera_named_lately_is_not_looked_at() -> None:
    """A map person seen within `KNOWN_S` where the body is (or as far off as they walked
    since) is who it is; seen longer ago, the body is nobody known."""
    body = ScanBody(id="scan_7", x=-2.0, y=0.0)
    seen = msgspec.structs.replace(entity("person_4", -2.3, 0.4, kind="person"), last_seen_ns=9 * S)
    assert glance_at([body], [seen], (0.0, 0.0), 0.0, 10 * S) is None
    walked = msgspec.structs.replace(seen, position_in_world=(-3.5, 0.0, 0.0),
                                     velocity_in_world=(1.0, 0.0))  # fmt: skip
    assert glance_at([body], [walked], (0.0, 0.0), 0.0, 10 * S) is None  # 1.5 <= 0.8 + 1.0
    walking = msgspec.structs.replace(seen, velocity_in_world=(0.5, 0.0))
    assert glance_at([body], [walking], (0.0, 0.0), 0.0, 12 * S) is not None  # 3 s ago
    # Seen standing there 20 s ago (seed 1's shift: one bystander, new tracks, three
    # turns in 40 s): still who it is; 40 s ago, nobody known.
    assert glance_at([body], [seen], (0.0, 0.0), 0.0, 29 * S) is None
    assert glance_at([body], [seen], (0.0, 0.0), 0.0, 49 * S) is not None
    never = msgspec.structs.replace(seen, last_seen_ns=0)
    assert glance_at([body], [never], (0.0, 0.0), 0.0, 1 * S) is not None
