"""A person's usual places: counted where the tracker fuses them, pooled on a merge, kept
with the map's entity."""

from __future__ import annotations

import math

import msgspec
import numpy as np

from common.config import SemanticMapSettings
from common.messages.semantic_map import MapEntity
from services.semantic_map.entities import IdBook, Observation, Track
from services.semantic_map.people import PeopleTracker
from services.semantic_map.whereabouts import CELL_M, EVERY_NS, MAX_PLACES, Whereabouts
from tests.unit.test_map_people import _hist, _standing, _walking

S = 1_000_000_000


def test_one_sighting_a_second_is_counted_in_its_cell_at_the_sightings_mean() -> None:
    w = Whereabouts()
    sway = [0.1 * math.sin(k) for k in range(25)]  # a worker standing at a bench, 10 Hz
    counted = [w.see((2.5 + sway[k], 3.5), k * S // 10) for k in range(25)]
    assert [k for k, c in enumerate(counted) if c] == [0, 10, 20]  # at 0, 1 and 2 s
    (place,) = w.places()
    assert place.sightings == 3 and place.last_seen_ns == 2 * S
    assert math.isclose(place.xy[0], 2.5 + (sway[0] + sway[10] + sway[20]) / 3)
    assert place.xy[1] == 3.5


def test_cells_are_ranked_by_sightings_then_by_the_latest() -> None:
    w = Whereabouts()
    t = 0
    for xy, n in (((0.5, 0.5), 2), ((5.5, 0.5), 4), ((9.5, 9.5), 2)):
        for _ in range(n):
            w.see(xy, t)
            t += EVERY_NS
    ranked = w.places()
    assert [p.xy for p in ranked] == [(5.5, 0.5), (9.5, 9.5), (0.5, 0.5)]
    assert [p.sightings for p in ranked] == [4, 2, 2]
    assert ranked[1].last_seen_ns > ranked[2].last_seen_ns


def test_a_new_cell_past_the_limit_replaces_the_least_seen_oldest() -> None:
    w = Whereabouts()
    t = 0
    for k in range(MAX_PLACES):
        for _ in range(1 if k == 3 else 2):
            w.see(((k + 0.5) * CELL_M, 0.5), t)
            t += EVERY_NS
    w.see((0.5, 40.5), t)
    xs = {round(p.xy[0] - 0.5) for p in w.places() if p.xy[1] < 1.0}
    assert len(w.places()) == MAX_PLACES
    assert 3 not in xs and len(xs) == MAX_PLACES - 1


def test_non_finite_places_are_not_counted() -> None:
    w = Whereabouts()
    assert not w.see((math.nan, 1.0), 0)
    assert w.places() == ()


def test_a_clock_that_went_back_counts_afresh() -> None:
    w = Whereabouts()
    assert w.see((1.0, 1.0), 500 * S)
    assert w.see((1.0, 1.0), 2 * S)  # a new run's sim time: not "within a second"
    assert not w.see((1.0, 1.0), 2 * S + EVERY_NS // 2)


def test_places_survive_the_entity_message_and_its_wire() -> None:
    w = Whereabouts()
    for k in range(6):
        w.see((1.2 + 2.0 * (k % 3), 4.4), k * EVERY_NS)
    track = Track("person", "person", np.array([1.2, 4.4]), np.eye(2) * 0.01, 0.0,
                  "perception", id="person_3", whereabouts=w)  # fmt: skip
    wire = msgspec.msgpack.encode(track.to_message())
    back = Track.from_message(msgspec.msgpack.decode(wire, type=MapEntity))
    assert back.whereabouts.places() == w.places()
    artifact = Track("bottle", "artifact", np.zeros(2), np.eye(2), 0.8, "perception",
                     id="bottle_1", whereabouts=w)  # fmt: skip
    assert artifact.to_message().places == ()


def _walker_tracker() -> tuple[PeopleTracker, list[tuple[float, float]]]:
    tracker = PeopleTracker(IdBook(), SemanticMapSettings())
    loop = [(float(x), 0.0) for x in np.arange(0.0, 10.0, 0.1)]  # 1 m/s along y = 0
    for k, xy in enumerate(loop):
        obs = Observation("person", np.array(xy), 0.0, 0.05)
        tracker.update(k * S // 10, [obs])
    return tracker, loop


def test_a_walker_tracked_by_the_map_leaves_the_cells_they_walked_through() -> None:
    tracker, _loop = _walker_tracker()
    (person,) = tracker.confirmed
    places = person.to_message().places
    xs = sorted(p.xy[0] for p in places)
    assert xs[0] < 1.0 and xs[-1] > 8.0  # the whole way walked
    assert all(abs(p.xy[1]) < 0.2 and p.sightings <= 2 for p in places)
    assert sum(p.sightings for p in places) == 10  # one a second over 9.9 s


def test_two_tracks_merged_into_one_person_pool_their_places() -> None:
    a, b = Whereabouts(), Whereabouts()
    a.see((0.5, 0.5), 0)
    a.see((3.5, 0.5), S)
    b.see((3.6, 0.4), 2 * S)
    b.see((7.5, 0.5), 3 * S)
    a.absorb(b)
    got = {(math.floor(p.xy[0]), p.sightings) for p in a.places()}
    assert got == {(0, 1), (3, 2), (7, 1)}
    assert a.last_ns == 3 * S


def test_a_person_known_again_by_their_clothes_keeps_the_places_of_both_tracks() -> None:
    """person_1 stood at (8, 0) and is seen a minute later walking elsewhere under a new
    track; once the map knows them again, their usual places hold both."""
    rng = np.random.default_rng(5)
    red, blue = _hist(2, rng), _hist(30, rng)
    tracker = PeopleTracker(IdBook(), SemanticMapSettings())
    t = _standing(tracker, 0, 10, [(8.0, 0.5), (0.5, 9.0)], [red, blue]) + 61 * S
    t = _walking(tracker, t, 30, (0.5, 0.5), (1.0, 0.0), red, seed=1)
    ((kept, _gone, _why),) = tracker.rejoin(t)
    cells = {math.floor(p.xy[0]) for p in kept.to_message().places}
    assert 8 in cells and {0, 1, 2} <= cells


def test_the_places_follow_every_sighting_and_pooling_after_they_were_ranked() -> None:
    w, other = Whereabouts(), Whereabouts()
    w.see((0.5, 0.5), 0)
    assert [p.sightings for p in w.places()] == [1]
    w.see((0.5, 0.5), S)
    assert [p.sightings for p in w.places()] == [2]
    other.see((4.5, 0.5), 0)
    w.absorb(other)
    assert [p.sightings for p in w.places()] == [2, 1]
