"""The usual place of a person looked at next: usual, not looked at yet, the nearest."""

from __future__ import annotations

from common.messages.semantic_map import SeenPlace
from services.mission.person_search import next_place

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
