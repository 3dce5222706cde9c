"""The map in and out as a file (`services.semantic_map.exchange`) and what a tick writes
(`services.semantic_map.commit`), on real SQLite files: a bad import is refused with a
typed reason before anything changes; a good one replaces the map, its database and its
views; a tick writes only what changed, the learned grid at most every 2 s."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from common.bus import RequestError
from common.config import SemanticMapSettings
from common.messages.base import NS_PER_S
from common.messages.semantic_map import MapFile
from services.semantic_map.commit import TickCommitter
from services.semantic_map.entities import Track
from services.semantic_map.exchange import check_import, export_map, import_map
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import OCCUPIED, Occupancy
from services.semantic_map.startup import save_all
from services.semantic_map.store import MapStore
from services.semantic_map.views import ViewHistory

MS = 1_000_000


def _map(obstacle: tuple[int, int] | None = None) -> SemanticMap:
    static = np.zeros((20, 20), np.uint8)
    if obstacle is not None:
        static[obstacle] = OCCUPIED
    occ = Occupancy(static, 0.5, (-5.0, -5.0), hits_needed=1)
    return SemanticMap(SemanticMapSettings(), occ, {})


def _track(entity_id: str, class_name: str, x: float) -> Track:
    kind = "person" if class_name == "person" else "artifact"
    return Track(
        class_name=class_name, kind=kind, xy=np.array([x, 0.0]), cov=np.eye(2) * 1e-4,
        z=0.8, source="seed-from-world", id=entity_id,
    )  # fmt: skip


def _stored(path: Path) -> dict[str, Any]:
    """Everything the database at `path` holds, comparable with ==."""
    store = MapStore(path)
    snap = store.load()
    store.close()
    return {
        "entities": [(msgspec.json.encode(e), app) for e, app in snap.entities],
        "counters": snap.counters,
        "grids": {
            k: (g.cells.tolist(), g.resolution_m, g.origin_xy) for k, g in snap.grids.items()
        },
        "meta": snap.meta,
    }


@pytest.fixture
def saved(tmp_path: Path) -> tuple[SemanticMap, MapStore, Path]:
    smap = _map()
    smap.add(_track("bottle_1", "bottle", 1.0))
    smap.stamp_ns = 7 * NS_PER_S
    path = tmp_path / "m.sqlite"
    store = MapStore(path)
    save_all(smap, store, {"start": "seed-from-world", "static_source": "none"})
    return smap, store, path


def test_a_bad_map_file_is_refused_with_a_reason_and_changes_nothing(
    saved: tuple[SemanticMap, MapStore, Path],
) -> None:
    smap, _store, path = saved
    before, entities = _stored(path), smap.entities("artifact")
    twice = MapFile(entities=[_track("can_1", "can", 0.0).to_message()] * 2)
    disagree = _track("person_1", "person", 0.0).to_message()
    disagree = msgspec.structs.replace(disagree, kind="artifact")
    for mf, why in ((twice, "names an id twice"), (MapFile(entities=[disagree]), "person_1")):
        with pytest.raises(RequestError) as refused:
            check_import(mf)
        assert refused.value.code == "invalid" and why in refused.value.message
    assert _stored(path) == before
    assert smap.entities("artifact") == entities


def test_an_import_replaces_the_map_its_database_and_its_views(
    saved: tuple[SemanticMap, MapStore, Path],
) -> None:
    smap, store, path = saved
    views = ViewHistory(period_ns=100 * MS, latency_ns=100 * MS)
    views.record(smap, -1)
    views.record(smap, 0)
    other = _map(obstacle=(3, 4))
    for tr in (_track("can_4", "can", 2.0), _track("person_2", "person", 3.0)):
        other.add(tr)
    other.ids.counters.update({"can": 4, "person": 2})
    mf = export_map(other)
    check_import(mf)
    summary = import_map(mf, smap, store, views)
    assert (summary.artifacts, summary.people, summary.missing) == (1, 1, 0)
    assert summary.stamp_ns == 7 * NS_PER_S
    assert [e.id for e in smap.entities("artifact")] == ["can_4"]
    assert smap.static_source == "file" and smap.occupancy.static[3, 4] == OCCUPIED
    stored = MapStore(path).load()
    assert [(e.id, e.source) for e, _ in stored.entities] == [
        ("can_4", "import"),
        ("person_2", "import"),
    ]
    assert stored.counters == {"can": 4, "person": 2}
    assert stored.meta["static_source"] == "file"
    assert stored.grids["static"].cells[3, 4] == OCCUPIED
    view = views.at(None)
    assert view is not None and view.tick_ns == 0  # the only view left: the map now
    assert views.at(50 * MS) is view
    assert [e.id for e in view.entities("artifact")] == ["can_4"]


def test_a_tick_writes_what_changed_and_the_learned_grid_at_most_every_2_s(
    saved: tuple[SemanticMap, MapStore, Path],
) -> None:
    smap, store, path = saved
    committer = TickCommitter(store)
    before = _stored(path)
    committer.commit(smap, 100 * MS)  # nothing changed: nothing written
    assert smap.stamp_ns == 7 * NS_PER_S
    assert _stored(path) == before
    smap.occupancy.integrate(np.array([[0.25, 0.25, 0.5]]))
    smap.grid_dirty = True
    committer.commit(smap, 1 * NS_PER_S)  # under 2 s since the last grid save (at 0)
    assert smap.grid_dirty and _stored(path) == before
    committer.commit(smap, 8 * NS_PER_S)
    assert not smap.grid_dirty and committer.last_grid_save == 8 * NS_PER_S
    after = _stored(path)
    assert after["meta"]["stamp_ns"] == str(8 * NS_PER_S) and smap.stamp_ns == 8 * NS_PER_S
    assert np.asarray(after["grids"]["learned"][0])[10, 10] == 1
    smap.add(_track("can_1", "can", 2.0))
    committer.commit(smap, 8 * NS_PER_S + 100 * MS)
    assert [e.id for e, _ in MapStore(path).load().entities] == ["bottle_1", "can_1"]
    smap.occupancy.integrate(np.array([[1.25, 0.25, 0.5]]))
    committer.close(smap)  # the learned layer as it ends, whatever the time
    assert np.asarray(_stored(path)["grids"]["learned"][0])[10, 12] == 1


def test_a_file_whose_grid_cannot_be_taken_changes_nothing_in_memory_or_on_disk(
    saved: tuple[SemanticMap, MapStore, Path],
) -> None:
    """`dume trial fuzz` imported a grid of int64 cells: the map was cleared, then the
    grid refused. Now the file is built first and refused whole; so is a file naming no
    site over a stack that has one."""
    from common.messages import to_wire
    from common.messages.semantic_map import OccupancyGrid

    smap, store, path = saved
    views = ViewHistory(period_ns=100 * MS, latency_ns=100 * MS)
    before, entities = _stored(path), smap.entities("artifact")
    good = export_map(smap)
    grids = {
        "int64 cells": np.zeros((4, 4), np.int64),
        "a 1-D grid": np.zeros(16, np.uint8),
        "cells of 7": np.full((4, 4), 7, np.uint8),
    }
    for why, cells in grids.items():
        grid = OccupancyGrid(stamp_ns=0, resolution_m=0.05, origin_xy=(0, 0), cells=to_wire(cells))
        mf = msgspec.structs.replace(good, occupancy=grid)
        with pytest.raises(RequestError, match="cannot be taken") as refused:
            import_map(mf, smap, store, views)
        assert refused.value.code == "invalid", why
    zero = OccupancyGrid(
        stamp_ns=0, resolution_m=0.0, origin_xy=(0, 0), cells=to_wire(np.zeros((4, 4), np.uint8))
    )
    with pytest.raises(RequestError, match="cell size"):
        import_map(msgspec.structs.replace(good, occupancy=zero), smap, store, views)
    with pytest.raises(RequestError, match="names no site"):
        check_import(msgspec.structs.replace(good, site=""), "small seed 0")
    assert _stored(path) == before
    assert smap.entities("artifact") == entities


def test_a_map_files_stamps_are_another_runs_clock_and_read_as_before_this_one() -> None:
    """A saved map's entity seen at 500 s of its run is, in this run, not seen since it
    started (0); one missing there is missing since before (0), not since 500 s."""
    from common.messages.semantic_map import MapEntity
    from services.semantic_map.mapfile import tracks_from_file

    def e(eid: str, missing: int | None) -> MapEntity:
        return MapEntity(id=eid, class_name="bottle", kind="artifact",
                         position_in_world=(1.0, 2.0, 0.8), uncertainty_m=0.05,
                         last_seen_ns=500 * NS_PER_S, source="perception",
                         missing_since_ns=missing)  # fmt: skip

    mf = MapFile(stamp_ns=600 * NS_PER_S, site="hall seed 0",
                 entities=[e("bottle_1", None), e("bottle_2", 550 * NS_PER_S)])  # fmt: skip
    tracks = tracks_from_file(mf, "prior")
    assert [(t.id, t.last_seen_ns, t.missing_since_ns, t.source) for t in tracks] == [
        ("bottle_1", 0, None, "prior"),
        ("bottle_2", 0, 0, "prior"),
    ]


def test_a_map_file_keeps_peoples_colours_and_refuses_a_histogram_that_is_not_one(
    saved: tuple[SemanticMap, MapStore, Path], tmp_path: Path
) -> None:
    """Saved after an exploration, the map knows its people's clothes: the next run can
    tell person_2 who walked off from somebody new (`PeopleTracker.reidentify`)."""
    from common.appearance import SIZE
    from services.semantic_map.mapfile import read_map_file, write_map_file

    smap, store, _path = saved
    other = _map()
    person = _track("person_2", "person", 3.0)
    look = np.linspace(1.0, 2.0, SIZE)
    person.appearance = look / look.sum()
    other.add(person)
    file = tmp_path / "hall.json"
    write_map_file(file, export_map(other))
    mf = read_map_file(file)
    assert list(mf.appearances) == ["person_2"]
    import_map(mf, smap, store, ViewHistory(100 * MS, 100 * MS))
    (back,) = smap.people.confirmed
    assert back.appearance is not None and np.allclose(
        back.appearance, person.appearance, atol=1e-4
    )
    bad = msgspec.structs.replace(mf, appearances={"person_2": [1.0, 2.0]})
    with pytest.raises(RequestError, match="person_2's colours"):
        import_map(bad, smap, store, ViewHistory(100 * MS, 100 * MS))
