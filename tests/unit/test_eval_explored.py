"""The explored map's entities judged from truth (`bench.eval.explored.score_entities`):
found within 10 cm with the right class, wrong class, misplaced, false entries, and
people found within half a metre, each named by its truth or map id."""

from __future__ import annotations

from common.messages.semantic_map import MapEntity
from services.sim.world import generate_world


def entity(eid: str, x: float, y: float) -> MapEntity:
    cls = eid.rsplit("_", 1)[0]
    kind = "person" if cls == "person" else "artifact"
    return MapEntity(
        id=eid, class_name=cls, kind=kind, position_in_world=(x, y, 0.9), uncertainty_m=0.02,
        last_seen_ns=0, source="perception",
    )  # fmt: skip


def test_found_wrong_misplaced_false_and_people() -> None:
    from bench.eval.explored import score_entities

    world = generate_world(0, "hall")
    a = world.artifacts
    arts = [
        entity(f"{x.object_class}_{i}", x.position[0] + 0.03, x.position[1])
        for i, x in enumerate(a[:3], 1)
    ]
    other = "can" if a[3].object_class != "can" else "box"
    arts.append(entity(f"{other}_9", a[3].position[0], a[3].position[1] - 0.05))  # wrong class
    arts.append(entity("box_8", a[4].position[0] + 0.2, a[4].position[1]))  # 20 cm off
    arts.append(entity("bottle_7", 50.0, 50.0))  # nothing there
    p = world.people
    people = [
        entity("person_1", p[0].position[0] + 0.3, p[0].position[1]),
        entity("person_2", 60.0, 0.0),
    ]
    s = score_entities(world, arts, people)
    assert s["artifacts"] == len(a)
    assert s["found_within_10cm"] == 4
    assert s["found_right_class"] == 3
    assert s["wrong_class"] == [f"{a[3].id} as {other}"]
    assert s["misplaced"] == [f"{a[4].id} 20 cm"]
    assert s["false_entries"] == ["bottle_7"]
    assert a[4].id in s["missed"] and a[0].id not in s["missed"]
    assert s["people_found"] == 1 and s["false_people"] == ["person_2"]
    assert p[0].id not in s["people_missed"]


def test_a_map_turned_in_its_own_frame_finds_its_artifacts_once_aligned() -> None:
    """The whole map turned 1° about the hall's middle (a start heading a little off):
    the far artifacts are more than 10 cm from their truth as it lies, all found once the
    map's alignment to the truth moves them back."""
    import numpy as np

    from bench.eval.explored import moved, score_entities
    from bench.map_agreement import Alignment

    world = generate_world(0, "hall")
    turn = Alignment(np.radians(1.0), (0.0, 0.0), (0.0, 0.0))
    arts = [
        entity(f"{x.object_class}_{i}", *turn.apply(np.array([x.position[:2]]))[0])
        for i, x in enumerate(world.artifacts, 1)
    ]
    assert score_entities(world, arts, [])["found_within_10cm"] < len(world.artifacts)
    back = Alignment(np.radians(-1.0), (0.0, 0.0), (0.0, 0.0))
    assert score_entities(world, moved(arts, back), [])["found_right_class"] == len(arts)
