"""Navigation's fast people layer: people perception saw, over the map's people."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.messages import semantic_map, world
from common.messages.arrays import to_wire
from common.messages.perception import Detection, Detections
from services.navigation.costmap import Person
from services.navigation.grid import Grid
from services.navigation.seen_people import SeenPeople, fitted_velocity

S = 1_000_000_000


def _det(cls: str, x: float, y: float, height: float = 1.2, map_id: str | None = None) -> Detection:
    return Detection(
        class_name=cls, score=0.9, bbox=(0, 0, 1, 1), mask=to_wire(np.ones((1, 1), np.uint8)),
        centroid_in_base_yaw=(x, y, 0.8), centroid_in_world=(x, y, 0.8), axis_in_world=(x, y, 0.8),
        extent=(0.4, 0.3, height), d_obj=1.0, theta_obj=0.0, n_points=100, map_id=map_id,
    )  # fmt: skip


def _frame(t: int, *dets: Detection) -> Detections:
    T = tuple(float(v) for v in np.eye(4).ravel())
    return Detections(stamp_ns=t, camera="camera_head", T_world_base=T, segmenter="truth",
                      detections=list(dets))  # fmt: skip


def test_a_person_seen_now_replaces_where_the_map_last_had_them() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 3.0, 0.2, map_id="person_2")))
    merged = seen.merge([Person("person_2", 3.4, 1.0), Person("person_1", -5.0, 0.0)], 0)
    assert [(p.id, p.x, p.y) for p in merged] == [("person_2", 3.0, 0.2), ("person_1", -5.0, 0.0)]


def test_a_sighting_lasts_its_ttl_and_short_blobs_and_other_classes_are_not_people() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 2.0, 0.0), _det("person", 1.0, 0.0, height=0.3),
                       _det("bottle", 1.5, 0.5)))  # fmt: skip
    assert [p.id for p in seen.active(S // 2)] == ["seen_1"]
    seen.update(_frame(S // 2))  # out of view: not gone
    assert len(seen.active(30 * S)) == 1
    assert seen.active(30 * S + S // 10) == []


def test_a_sighting_kept_out_of_view_says_when_it_was_seen() -> None:
    """A sighting kept for seconds is no person seen now: it carries its frame's stamp
    (hall seed 4's shift: a walker's last sighting beside the flank, kept as seen now,
    could never go stale, and the robot waited 23 s for it to pass)."""
    seen = SeenPeople()
    seen.update(_frame(2 * S, _det("person", 2.0, 0.0)))
    seen.update(_frame(3 * S))  # out of view
    assert [(p.id, p.seen_ns) for p in seen.active(12 * S)] == [("seen_1", 2 * S)]
    (merged,) = seen.merge([], 12 * S)
    assert merged.seen_ns == 2 * S


def test_a_person_seen_elsewhere_hides_where_the_map_last_had_them_under_their_id() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 3.0, 2.6, map_id="person_2")))
    merged = seen.merge([Person("person_2", 3.0, 0.0)], 0)  # the map: still in the path
    assert [(p.id, p.x, p.y) for p in merged] == [("person_2", 3.0, 2.6)]


def _grid_with_a_machine() -> Grid:
    """A 4 × 4 m grid of 5 cm cells at the origin; a machine fills x 1.75–2.75, y 2–3;
    the row y 3.5–4 is unknown."""
    cells = np.zeros((80, 80), np.uint8)
    cells[40:60, 35:55] = world.OCCUPIED
    cells[70:, :] = 255
    return Grid.from_map(
        semantic_map.OccupancyGrid(stamp_ns=0, resolution_m=0.05, origin_xy=(0.0, 0.0),
                                   cells=to_wire(cells))
    )  # fmt: skip


def test_a_person_inside_or_on_the_face_of_an_obstacle_is_not_a_person() -> None:
    """Hall seed 4: a machine's face read as a person in every frame stopped the robot."""
    grid = _grid_with_a_machine()
    seen = SeenPeople()
    seen.update(
        _frame(0, _det("person", 1.75, 2.5), _det("person", 2.2, 2.4), _det("person", 1.5, 2.5)),
        grid,
    )
    assert [(p.x, p.y) for p in seen.active(0)] == [(1.5, 2.5)], "a real person 25 cm off stays"


def test_unknown_cells_do_not_hide_a_person() -> None:
    """A patrol starts with the map unknown: everyone seen must still count."""
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 1.0, 3.75)), _grid_with_a_machine())
    assert len(seen.active(0)) == 1


def test_a_person_seen_walking_gets_their_velocity_once_the_sightings_span_enough_time() -> None:
    """10 Hz sightings of a walker at 1.0 m/s along +x with 2 cm of jitter: no velocity in
    the first 0.25 s, then within 0.3 m/s of the truth (4 points), 0.15 m/s once the
    0.6 s window is full; a second person standing beside keeps a track of their own and
    about zero."""
    rng = np.random.default_rng(0)
    seen = SeenPeople()
    for k in range(8):
        t = k * S // 10
        jitter = rng.normal(0.0, 0.02, 4)
        seen.update(_frame(t, _det("person", 1.0 + 0.1 * k + jitter[0], 0.0 + jitter[1]),
                           _det("person", 3.0 + jitter[2], 2.0 + jitter[3])))  # fmt: skip
        people = {p.id: p for p in seen.active(t)}
        assert set(people) == {"seen_1", "seen_2"}
        walker, stander = people["seen_1"], people["seen_2"]
        if k < 3:
            assert walker.velocity is None
            continue
        assert walker.velocity is not None and stander.velocity is not None
        tol = 0.15 if k >= 6 else 0.3
        assert math.dist(walker.velocity, (1.0, 0.0)) < tol
        assert math.hypot(*stander.velocity) < tol


def test_a_sighting_seen_walking_and_gone_from_view_is_dropped_as_the_lidars_tracks_end() -> None:
    """Hall seed 5's shift: a walker gone by beside the flank, where neither lidar sees,
    was kept at their last sighting for its 30 s and held the robot 20 s with nobody
    there. Walking when last seen, a sighting lasts `walker_ttl_s` out of view; standing,
    its `ttl_s`."""
    seen = SeenPeople()
    for k in range(6):  # a walker at 1 m/s along +x and a person standing, 10 Hz
        seen.update(_frame(k * S // 10, _det("person", 1.0 + 0.1 * k, 0.0),
                           _det("person", 3.0, 2.0)))  # fmt: skip
    seen.update(_frame(S))  # both out of view
    last = S // 2
    assert {q.id for q in seen.active(last + 3 * S)} == {"seen_1", "seen_2"}
    assert {q.id for q in seen.active(last + 3 * S + S // 10)} == {"seen_2"}  # walked on
    assert {q.id for q in seen.active(last + 30 * S)} == {"seen_2"}


def test_a_person_seen_too_briefly_keeps_the_velocity_the_maps_tracker_has_for_them() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 2.0, 0.0, map_id="person_3")))
    merged = seen.merge([Person("person_3", 2.1, 0.0, None, (0.0, -0.8))], 0)
    assert [(p.id, p.x, p.velocity) for p in merged] == [("person_3", 2.0, (0.0, -0.8))]


def test_a_glimpse_too_brief_for_a_velocity_is_a_walker_then_stands_once_not_seen_again() -> None:
    """Hall seed 1's shift: one glimpse of a worker standing beside the trunk, kept its 30 s
    as a walker at 1.6 m/s (S_p at rest 1.52 m), held the robot 23 s 0.65 m from them."""
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 1.0, 0.8)))
    assert [q.velocity for q in seen.active(S)] == [None]  # maybe walking at the robot
    assert [q.velocity for q in seen.active(3 * S)] == [(0.0, 0.0)]  # not seen walking
    seen.update(_frame(4 * S, _det("person", 1.0, 0.8)))  # seen again: a glimpse again
    assert [q.velocity for q in seen.active(4 * S)] == [None]


def test_a_velocity_is_a_least_squares_slope() -> None:
    pts = [(k * S // 10, 0.5 * k / 10, -0.2 * k / 10) for k in range(5)]
    v = fitted_velocity(pts, 0.25)
    assert v is not None and v == pytest.approx((0.5, -0.2))
    assert fitted_velocity(pts[:2], 0.05) is None  # two points are no fit
    assert fitted_velocity(pts[:3], 0.25) is None  # 0.2 s: too short


def test_a_sighting_without_a_map_id_beside_a_map_person_is_that_person_under_their_id() -> None:
    """Hall seed 5: the camera saw the handover's person with no map id: `seen_5` took
    their place in the layer under its own id, and the handover's rules, which go by id,
    no longer knew them. Within `named_m` the map's id is theirs, the nearest first; a
    sighting farther off, or a second one by the same map person, keeps its own."""
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 1.75, -1.95), _det("person", 4.0, 4.0),
                       _det("person", 2.1, -2.5)))  # fmt: skip
    mapped = [Person("person_3", 1.89, -2.03), Person("person_1", 6.0, 6.0)]
    merged = seen.merge(mapped, 0)
    got = sorted((p.id, p.x, p.y) for p in merged)
    assert got == [("person_1", 6.0, 6.0), ("person_3", 1.75, -1.95), ("seen_2", 4.0, 4.0),
                   ("seen_3", 2.1, -2.5)]  # fmt: skip
    assert seen.seen_since(0) == {"person_3", "seen_2", "seen_3"}  # as the layer names them


def test_a_map_person_a_sighting_already_names_gives_no_second_sighting_their_id() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 1.9, -2.0, map_id="person_3"), _det("person", 1.5, -2.2)))
    merged = seen.merge([Person("person_3", 1.89, -2.03)], 0)
    assert sorted(p.id for p in merged) == ["person_3", "seen_1"]
