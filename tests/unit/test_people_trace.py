"""The map's people trace replays to the map it was written from, and the id bench scores
one id per person as 1 and a swap as a swap."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.people_ids import score
from common.appearance import SIZE
from common.camera import PinholeCamera
from common.config import SemanticMapSettings
from services.semantic_map.entities import Observation, Track
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.people_trace import PeopleTrace, read_trace, replay

S = 1_000_000_000


def _look(peak: int) -> np.ndarray:
    h = np.full(SIZE, 0.01)
    h[peak] += 1.0
    return h / h.sum()


def _person(xy: np.ndarray, peak: int, range_m: float) -> Observation:
    return Observation("person", xy, 0.0, 0.05, 0.9, _look(peak), range_m, True)


def _camera_at(x: float) -> PinholeCamera:
    """A camera at (x, 0, 1) looking along the world's +x, depth 8 m everywhere."""
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = (x, 0.0, 1.0)
    return PinholeCamera(160.0, 160.0, 160.0, 120.0, T, np.full((240, 320), 8.0, np.float32))


def test_a_replayed_trace_gives_the_ids_and_places_the_live_map_gave(tmp_path: Path) -> None:
    settings = SemanticMapSettings()
    live = SemanticMap(settings, Occupancy.unknown(1.0, 0.05), {"person": 4})
    live.add(Track("person", "person", np.array([3.0, 1.0]), np.eye(2) * 0.01, 0.0, "prior",
                   id="person_2"))  # fmt: skip
    live.people.tracks[0].appearance = _look(5)
    path = tmp_path / "people.trace"
    trace = PeopleTrace(path)
    trace.start(live)
    live.people_trace = trace
    rng = np.random.default_rng(0)
    for k in range(60):  # one walks across while the other stands, then the stander leaves
        t = k * S // 10
        walker = np.array([1.0 + 0.05 * k, -1.0]) + rng.normal(0, 0.02, 2)
        people = [_person(walker, 20, 2.0)]
        if k < 30:
            people.append(_person(np.array([3.0, 1.0]) + rng.normal(0, 0.02, 2), 5, 3.0))
        cam = _camera_at(0.0) if k % 2 else None
        live.fuse(t, [], people, cam)
        trace.frame(t, people, cam)
    trace.close()
    records = list(read_trace(path))
    assert len(records) == 61
    *_, (frame, replayed, _) = replay(path, settings)
    assert frame.stamp_ns == 59 * S // 10
    want = {t.id: (t.xy.round(6).tolist(), t.hits, t.misses) for t in live.people.confirmed}
    got = {t.id: (t.xy.round(6).tolist(), t.hits, t.misses) for t in replayed.people.confirmed}
    assert got == want and "person_2" in got and "person_5" in got


def test_a_cut_short_last_record_ends_the_trace(tmp_path: Path) -> None:
    smap = SemanticMap(SemanticMapSettings(), Occupancy.unknown(1.0, 0.05), {})
    path = tmp_path / "people.trace"
    trace = PeopleTrace(path)
    trace.start(smap)
    trace.frame(1, [], None)
    trace.close()
    whole = path.read_bytes()
    path.write_bytes(whole[:-3])
    assert len(list(read_trace(path))) == 1


def test_one_id_throughout_scores_one_and_a_change_of_id_is_a_switch() -> None:
    steady = score([(0, {"a": (0.0, 0.0), "b": (5.0, 0.0)},
                     {"person_1": (0.2, 0.0), "person_2": (5.1, 0.1)})] * 10)  # fmt: skip
    assert steady.idf1 == 1.0 and steady.switches == 0 and not steady.shared
    split = score(
        [(k * S, {"a": (0.0, 0.0)}, {"person_1": (0.1, 0.0)}) for k in range(6)]
        + [(k * S, {"a": (0.0, 0.0)}, {"person_7": (0.1, 0.0)}) for k in range(6, 10)]
    )
    assert split.switches == 1 and split.ids_per_person == {"a": ["person_1", "person_7"]}
    assert split.idtp == 6 and split.idfn == 4 and split.idfp == 4
    assert abs(split.idf1 - 0.6) < 1e-9
    assert split.timeline == {"a": [["person_1", 0.0, 5.0], ["person_7", 6.0, 9.0]]}


def test_one_id_on_two_people_is_shared_and_an_id_on_nobody_a_ghost() -> None:
    s = score(
        [(0, {"a": (0.0, 0.0)}, {"person_1": (0.1, 0.0), "person_9": (4.0, 4.0)})] * 3
        + [(0, {"b": (2.0, 0.0)}, {"person_1": (2.1, 0.0)})] * 3
    )
    assert s.shared == {"person_1": ["a", "b"]}
    assert s.ghosts == ["person_9"]
    far = score([(0, {"a": (0.0, 0.0)}, {"person_1": (1.5, 0.0)})])
    assert far.idtp == 0 and far.ghosts == ["person_1"]
