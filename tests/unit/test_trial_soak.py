"""The soak's own arithmetic: the growth figure, and the map it imports between requests."""

from __future__ import annotations

from bench.trial_soak import growth, renumbered
from common.messages.semantic_map import MapEntity, MapFile


def _entity(id_: str, class_name: str, kind: str) -> MapEntity:
    return MapEntity(id=id_, class_name=class_name, kind=kind, position_in_world=(1.0, 2.0, 0.8),
                     uncertainty_m=0.05, last_seen_ns=0, source="import")  # fmt: skip


def test_renumbered_gives_every_artifact_the_next_free_id_and_keeps_the_people() -> None:
    mf = MapFile(
        entities=[
            _entity("bottle_1", "bottle", "artifact"),
            _entity("can_2", "can", "artifact"),
            _entity("person_3", "person", "person"),
        ],
        counters={"bottle": 1, "can": 2, "person": 3},
    )
    once = renumbered(mf)
    assert [e.id for e in once.entities] == ["bottle_2", "can_3", "person_3"]
    assert once.counters == {"bottle": 2, "can": 3, "person": 3}
    assert [e.id for e in renumbered(once).entities] == ["bottle_3", "can_4", "person_3"]
    assert [e.position_in_world for e in once.entities] == [
        e.position_in_world for e in mf.entities
    ]


def test_growth_runs_from_the_second_tenth_to_the_last_and_skips_unread_samples() -> None:
    flat = [{"rss_kb": 100} for _ in range(20)]
    assert growth(flat, "rss_kb") == 0.0
    rising = [{"rss_kb": 100 + k} for k in range(20)] + [{"rss_kb": -1}]
    assert growth(rising, "rss_kb") == 15.61  # median 102.5 → 118.5
    assert growth(flat[:9], "rss_kb") is None
