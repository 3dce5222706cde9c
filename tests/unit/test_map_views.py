"""The map as of a tick (`services.semantic_map.views`): what a lockstep consumer reads."""

from __future__ import annotations

import numpy as np
import pytest

from common.bus import RequestError
from common.config import SemanticMapSettings
from common.keys import as_of
from services.semantic_map import queries
from services.semantic_map.entities import Track
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import OCCUPIED, Occupancy
from services.semantic_map.views import KEPT, ViewHistory, view_of

MS = 1_000_000


def _map() -> SemanticMap:
    occ = Occupancy(np.zeros((20, 20), np.uint8), 0.5, (-5.0, -5.0), hits_needed=1)
    return SemanticMap(SemanticMapSettings(), occ, {})


def _bottle() -> Track:
    return Track(
        class_name="bottle", kind="artifact", xy=np.array([0.0, 0.0]), cov=np.eye(2) * 1e-4,
        z=0.8, source="seed-from-world", id="bottle_1",
    )  # fmt: skip


def test_a_consumer_reads_the_map_of_the_last_tick_that_takes_effect_by_its_time() -> None:
    smap = _map()
    views = ViewHistory(period_ns=100 * MS, latency_ns=100 * MS)
    views.add(view_of(smap, -1, None))
    bottle = _bottle()
    for b in range(0, 500 * MS, 100 * MS):  # the map has its bottle at x = b every tick
        if b == 0:
            smap.add(bottle)
        bottle.xy = np.array([b / 1e9, 0.0])
        views.add(view_of(smap, b, views.newest))
    assert views.due_tick(250 * MS) == 100 * MS
    seen = views.at(250 * MS)
    assert seen is not None and seen.tick_ns == 100 * MS
    assert seen.entity("artifact", "bottle_1").position_in_world[0] == pytest.approx(0.1)  # type: ignore[union-attr]
    before_any = views.at(50 * MS)  # nothing takes effect before the first tick + latency
    assert before_any is not None and before_any.tick_ns == -1
    assert before_any.entity("artifact", "bottle_1") is None
    now = views.at(None)
    assert now is not None and now.tick_ns == 400 * MS


def test_the_grid_is_built_again_only_when_its_cells_changed() -> None:
    smap = _map()
    first = view_of(smap, 0, None)
    assert view_of(smap, 100 * MS, first).occupancy is first.occupancy
    smap.occupancy.integrate(np.array([[0.25, 0.25, 0.5]]))  # a learned obstacle
    changed = view_of(smap, 200 * MS, first)
    assert changed.occupancy is not first.occupancy
    assert smap.occupancy.cells()[10, 10] == OCCUPIED
    again = view_of(smap, 300 * MS, changed)
    smap.occupancy.integrate(np.array([[0.25, 0.25, 0.5]]))  # the same cell: no change
    assert view_of(smap, 400 * MS, again).occupancy is changed.occupancy


def test_views_are_kept_for_a_while_and_an_old_time_gets_the_oldest() -> None:
    smap = _map()
    views = ViewHistory(period_ns=100 * MS, latency_ns=100 * MS)
    for b in range(0, (KEPT + 5) * 100 * MS, 100 * MS):
        views.add(view_of(smap, b, views.newest))
    oldest = views.at(0)
    assert oldest is not None and oldest.tick_ns == 5 * 100 * MS


def test_at_is_split_off_the_selector_and_checked() -> None:
    key = "dume/map/artifacts"
    assert as_of(key, None) == key
    assert queries.split_at(as_of(key, 1500)) == (key, 1500)
    assert queries.split_at(as_of(f"{key}?class=bottle", 7)) == (f"{key}?class=bottle", 7)
    assert queries.split_at(f"{key}?class=can") == (f"{key}?class=can", None)
    with pytest.raises(RequestError, match="integer nanoseconds"):
        queries.split_at(f"{key}?at=soon")


def test_a_person_merged_into_another_is_found_under_their_old_id() -> None:
    """The map found person_21 and person_2 one person and kept person_2: a request for
    person_21 still finds them, in the map now and as of a tick (not as an alias loop)."""
    from services.semantic_map.mapper import resolve_alias

    smap = _map()
    person = Track(
        class_name="person", kind="person", xy=np.array([1.0, 2.0]), cov=np.eye(2) * 1e-2,
        z=0.0, source="perception", id="person_2",
    )  # fmt: skip
    smap.add(person)
    smap.aliases.update({"person_21": "person_2", "person_30": "person_21"})
    assert resolve_alias(smap.aliases, "person_30") == "person_2"
    assert resolve_alias({"a_1": "a_2", "a_2": "a_1"}, "a_1") == "a_2"  # a loop ends
    got = smap.entity("person", "person_21")
    assert got is not None and got.id == "person_2"
    view = view_of(smap, 0, None)
    got = queries.one(view, "person", "dume/map/people/person_30")
    assert got.id == "person_2"
    with pytest.raises(RequestError):
        queries.one(view, "person", "dume/map/people/person_9")
