"""What the robot took away is missing at its place (`SemanticMap.taken`): the entry of
its class nearest where the jaw closed, and the entry the mission picked it as, once, and
not an entry the map saw again after the take."""

from __future__ import annotations

import numpy as np

from common.config import SemanticMapSettings
from common.messages.mission import Taken
from services.semantic_map.entities import Track
from services.semantic_map.mapper import TAKEN_GRACE_S, SemanticMap
from services.semantic_map.occupancy import Occupancy

S = 1_000_000_000


def _bottle(map_id: str, x: float, y: float, seen_s: float = 1.0) -> Track:
    return Track(class_name="bottle", kind="artifact", xy=np.array([x, y]),
                 cov=np.eye(2) * 0.05**2, z=0.8, source="perception", id=map_id,
                 last_seen_ns=round(seen_s * S))  # fmt: skip


def _map(*tracks: Track) -> SemanticMap:
    occ = Occupancy(np.zeros((20, 20), np.uint8), 0.5, (-5.0, -5.0), hits_needed=3)
    smap = SemanticMap(SemanticMapSettings(), occ, {})
    for tr in tracks:
        smap.add(tr)
    smap.take_changes()
    return smap


def _missing(smap: SemanticMap) -> dict[str, int | None]:
    return {e.id: e.missing_since_ns for e in smap.entities("artifact")}


def test_a_take_marks_the_entry_where_the_jaw_closed_and_the_one_picked_as() -> None:
    """Hall seed 0's shift: the fetch of bottle_8 (a phantom 0.3 m off) closed on
    bottle_1; both are marked, the bottle 0.6 m away and the box are not."""
    smap = _map(_bottle("bottle_1", 5.12, -0.23), _bottle("bottle_8", 5.02, 0.07),
                _bottle("bottle_5", 4.50, 0.20))  # fmt: skip
    take = Taken(stamp_ns=10 * S, map_id="bottle_8", class_name="bottle", xy=(5.10, -0.22))
    marked = smap.taken([take])
    assert sorted(i for i, _ in marked) == ["bottle_1", "bottle_8"]
    assert _missing(smap) == {"bottle_1": 10 * S, "bottle_5": None, "bottle_8": 10 * S}
    changed, _ = smap.take_changes()
    assert {tr.id for tr in changed} == {"bottle_1", "bottle_8"}  # written to the database
    assert smap.taken([take]) == []  # once


def test_a_take_read_again_does_not_mark_what_the_map_saw_after_it() -> None:
    """Put back and seen there later (or the take read again after a map restart)."""
    late = 10.0 + TAKEN_GRACE_S + 1.0
    smap = _map(_bottle("bottle_1", 1.0, 0.0, seen_s=late))
    take = Taken(stamp_ns=10 * S, map_id="bottle_1", class_name="bottle", xy=(1.0, 0.0))
    assert smap.taken([take]) == []
    assert _missing(smap) == {"bottle_1": None}


def test_a_take_far_from_every_entry_of_its_class_marks_nothing() -> None:
    smap = _map(_bottle("bottle_1", 1.0, 0.0), _bottle("bottle_2", 3.0, 0.0))
    take = Taken(stamp_ns=10 * S, map_id="bottle_2", class_name="bottle", xy=(2.0, 0.0))
    assert smap.taken([take]) == []
