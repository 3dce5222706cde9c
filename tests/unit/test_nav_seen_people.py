"""Navigation's fast people layer: people perception saw, over the map's people."""

from __future__ import annotations

import numpy as np

from common.messages.arrays import to_wire
from common.messages.perception import Detection, Detections
from services.navigation.costmap import Person
from services.navigation.seen_people import SeenPeople

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


def test_a_person_seen_elsewhere_hides_where_the_map_last_had_them_under_their_id() -> None:
    seen = SeenPeople()
    seen.update(_frame(0, _det("person", 3.0, 2.6, map_id="person_2")))
    merged = seen.merge([Person("person_2", 3.0, 0.0)], 0)  # the map: still in the path
    assert [(p.id, p.x, p.y) for p in merged] == [("person_2", 3.0, 2.6)]
