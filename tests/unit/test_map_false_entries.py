"""False entries of the map: an artifact the map made itself from a few detections and
then did not see when it looked at its place is deleted (in the database too, with the
reason), while prior, seeded and well-observed artifacts are only marked missing."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np

from common.config import SemanticMapSettings
from common.geometry import make_T
from common.messages import to_wire
from common.messages.perception import Detection, Detections
from common.messages.sim import CameraFrame
from common.robot_description import R_FORWARD_OPTICAL
from services.semantic_map.entities import Track
from services.semantic_map.mapper import IngestReport, SemanticMap
from services.semantic_map.occupancy import OCCUPIED, Occupancy
from services.semantic_map.store import MapStore
from tests.unit.map_fakes import detection

S = 100_000_000
W, H = 320, 240
T_WORLD_BASE = np.eye(4)
#: The head camera 0.8 m up looking along world +x; depth 5 m everywhere (nothing hides).
T_BASE_CAMERA = make_T(R_FORWARD_OPTICAL, (0.0, 0.0, 0.8))
BOX_XY, CAN_XY, BOTTLE_XY = (1.5, 0.0), (1.5, -0.4), (1.5, 0.4)


def _frame(t: int) -> CameraFrame:
    return CameraFrame(
        stamp_ns=t,
        camera="camera_head",
        width=W,
        height=H,
        fx=200.0,
        fy=200.0,
        cx=(W - 1) / 2,
        cy=(H - 1) / 2,
        rgb=to_wire(np.zeros((H, W, 3), np.uint8)),
        depth=to_wire(np.full((H, W), 5.0, np.float32)),
        T_base_camera=tuple(T_BASE_CAMERA.ravel().tolist()),
    )


def _det(cls: str, xy: tuple[float, float]) -> Detection:
    return detection(cls, *xy)


def _ingest(smap: SemanticMap, t: int, *dets: Detection) -> IngestReport:
    msg = Detections(
        stamp_ns=t,
        camera="camera_head",
        T_world_base=tuple(T_WORLD_BASE.ravel().tolist()),
        segmenter="network",
        detections=list(dets),
    )
    return smap.ingest(msg, _frame(t))


def _map(drop_below: int = 5) -> SemanticMap:
    occ = Occupancy(np.zeros((20, 20), np.uint8), 0.5, (-5.0, -5.0), hits_needed=3)
    return SemanticMap(SemanticMapSettings(drop_below_observations=drop_below), occ, {})


def _seeded_bottle() -> Track:
    return Track(
        class_name="bottle",
        kind="artifact",
        xy=np.array(BOTTLE_XY),
        cov=np.eye(2) * 0.05**2,
        z=0.5,
        source="seed-from-world",
        id="bottle_1",
    )


def _commit(smap: SemanticMap, store: MapStore) -> None:
    """What the node does at the end of a tick."""
    changed, counters = smap.take_changes()
    store.commit(
        [(t.to_message(), t.appearance) for t in changed],
        counters,
        deleted=smap.take_deletions(),
    )


def _run(smap: SemanticMap, store: MapStore | None = None) -> list[IngestReport]:
    """A box seen twice and a can seen six times (both made by the map), then eight frames
    looking at their places (and the seeded bottle's) and seeing nothing."""
    reports = []
    for k in range(1, 15):
        dets = []
        if k <= 2:
            dets.append(_det("box", BOX_XY))
        if k <= 6:
            dets.append(_det("can", CAN_XY))
        reports.append(_ingest(smap, k * S, *dets))
        if store is not None:
            _commit(smap, store)
    return reports


def test_a_false_entry_made_from_few_detections_is_deleted_when_not_seen() -> None:
    smap = _map()
    smap.add(_seeded_bottle())
    reports = _run(smap)
    created = [i for r in reports for i in r.new_ids]
    assert created == ["box_1", "can_1"]
    dropped = [d for r in reports for d in r.dropped]
    assert [i for i, _ in dropped] == ["box_1"]
    assert "2 detection(s)" in dropped[0][1] and "not seen" in dropped[0][1]
    ids = {e.id: e for e in smap.entities("artifact")}
    assert "box_1" not in ids
    # the well-observed can and the seeded bottle are only marked missing
    assert ids["can_1"].missing_since_ns is not None
    assert ids["bottle_1"].missing_since_ns is not None
    assert smap.take_deletions() == ["box_1"]


def test_an_artifact_seen_only_from_afar_then_not_seen_from_near_is_deleted() -> None:
    smap = _map(drop_below=5)
    far, near = msgspec.structs.replace(_det("box", CAN_XY), d_obj=3.5), _det("can", BOX_XY)
    for k in range(1, 21):  # a box from 3.5 m twenty times (well observed), a can from near
        _ingest(smap, k * S, far, msgspec.structs.replace(near, d_obj=1.8))
    reports = [_ingest(smap, k * S) for k in range(21, 30)]  # then near looks see neither
    dropped = [d for r in reports for d in r.dropped]
    assert [i for i, _ in dropped] == ["box_1"]
    assert "seen 20 times, only from beyond 2 m (nearest 3.5 m)" in dropped[0][1]
    can = smap.entity("artifact", "can_1")
    assert can is not None and can.missing_since_ns is not None  # seen from near: missing


def test_the_threshold_is_configurable_and_zero_keeps_every_entry() -> None:
    smap = _map(drop_below=0)
    reports = _run(smap)
    assert not [d for r in reports for d in r.dropped]
    assert smap.entity("artifact", "box_1") is not None
    smap = _map(drop_below=10)
    reports = _run(smap)
    assert sorted(i for r in reports for i, _ in r.dropped) == ["box_1", "can_1"]


def test_a_deleted_entry_is_gone_from_the_database_and_its_id_is_never_reused(
    tmp_path: Path,
) -> None:
    store = MapStore(tmp_path / "m.sqlite")
    smap = _map()
    smap.add(_seeded_bottle())
    _run(smap, store)
    store.close()
    snap = MapStore(tmp_path / "m.sqlite").load()
    stored = {e.id: e for e, _ in snap.entities}
    assert sorted(stored) == ["bottle_1", "can_1"]
    assert stored["can_1"].missing_since_ns is not None
    assert snap.counters["box"] == 1
    # a restarted map gives the next box a new number
    again = SemanticMap(SemanticMapSettings(), smap.occupancy, snap.counters)
    for e, app in snap.entities:
        again.add(Track.from_message(e, app))
    for k in (20, 21):
        report = _ingest(again, k * S, _det("box", (2.0, 1.0)))
    assert report.new_ids == ["box_2"]


def test_writes_and_deletions_of_one_tick_land_together(tmp_path: Path) -> None:
    store = MapStore(tmp_path / "m.sqlite")
    a, b = _seeded_bottle(), _seeded_bottle()
    b.id = "bottle_2"
    store.commit([(a.to_message(), None), (b.to_message(), None)], {"bottle": 2})
    b.missing_since_ns = 5
    store.commit([(b.to_message(), None)], deleted=["bottle_1", "bottle_9"])
    snap = store.load()
    assert [(e.id, e.missing_since_ns) for e, _ in snap.entities] == [("bottle_2", 5)]
    assert store.integrity() == "ok"


def test_a_detection_beyond_the_validated_range_is_not_fused() -> None:
    smap = _map()
    far = _det("person", (140.0, 130.0))  # a depth read through to the background
    near = _det("person", (3.0, 0.0))
    for k in range(1, 4):
        report = _ingest(smap, k * S, far, near)
        assert report.ignored >= 1
    people = [tr for tr in smap.tracks() if tr.class_name == "person"]
    assert people and all(float(np.hypot(*tr.xy)) < 8.0 for tr in people)


def test_a_person_made_from_a_few_detections_then_not_seen_is_deleted() -> None:
    """A split track or a false positive: two detections, then five looks at chest height
    that find nobody. A person seen often is kept when not seen (they walk away), and one
    hidden behind something nearer is not looked at at all."""
    smap = _map()
    reports = []
    for k in range(1, 15):
        dets = [_det("person", (3.0, 0.0))] if k <= 2 else []
        dets += [_det("person", (4.0, 1.5))] if k <= 6 else []
        reports.append(_ingest(smap, k * S, *dets))
    created = [i for r in reports for i in r.new_ids]
    assert created == ["person_1", "person_2"]
    dropped = [d for r in reports for d in r.dropped]
    assert [i for i, _ in dropped] == ["person_1"]
    assert "2 detection(s)" in dropped[0][1]
    assert [e.id for e in smap.entities("person")] == ["person_2"]  # 6 hits, drop_below 5
    assert smap.take_deletions() == ["person_1"]


def test_a_hidden_person_is_not_counted_missed() -> None:
    smap = _map()
    for k in (1, 2):
        _ingest(smap, k * S, _det("person", (3.0, 0.0)))
    for k in range(3, 12):  # a wall 1 m in front of the camera: the frame says nothing
        frame = msgspec.structs.replace(
            _frame(k * S), depth=to_wire(np.full((H, W), 1.0, np.float32))
        )
        msg = Detections(
            stamp_ns=k * S,
            camera="camera_head",
            T_world_base=tuple(T_WORLD_BASE.ravel().tolist()),
            segmenter="network",
            detections=[],
        )
        assert not smap.ingest(msg, frame).dropped
    assert [e.id for e in smap.entities("person")] == ["person_1"]


def test_a_person_on_a_static_obstacle_is_not_a_person_and_hides_no_artifact() -> None:
    """Hall patrol: a bench read as a person, the can on it then dropped as clothes. With
    the bench in the static layer the "person" is ignored and the can is mapped; a real
    person half a metre in front of the bench is."""
    static = np.zeros((40, 40), np.uint8)
    static[18:22, 24:28] = OCCUPIED  # a bench: x 1.0–2.0 (res 0.25, origin −5), y −0.5–0.5
    smap = SemanticMap(SemanticMapSettings(), Occupancy(static, 0.25, (-5.0, -5.0)), {})
    for k in range(1, 4):
        _ingest(smap, k * S, _det("person", (1.5, 0.0)), _det("can", (1.45, 0.05)),
                _det("person", (0.5, 2.0)))  # fmt: skip
    assert [e.id for e in smap.entities("artifact")] == ["can_1"]
    people = smap.entities("person")
    assert [(e.id, round(e.position_in_world[0], 2)) for e in people] == [("person_1", 0.5)]


def test_on_a_lidar_map_a_person_standing_is_a_person_and_a_bench_is_not() -> None:
    """The SLAM grid maps whoever stood still as a blob: a person there is still a person
    (and the bottle-like hand on them is dropped as clothes), while a "person" read on the
    bench, a blob longer than a person, is ignored and the can on it is mapped."""
    static = np.zeros((80, 80), np.uint8)
    static[38:42, 48:56] = OCCUPIED  # a bench: x 1.0–2.0, y −0.25–0.25 (0.125 m cells)
    static[47:49, 28:30] = OCCUPIED  # a person standing at x −1.5–1.25, y 0.875–1.125
    occ = Occupancy(np.full((80, 80), 255, np.uint8), 0.125, (-5.0, -5.0))
    occ.adopt_static(static)
    smap = SemanticMap(SemanticMapSettings(), occ, {})
    for k in range(1, 4):
        _ingest(smap, k * S, _det("person", (2.0, 0.0)), _det("can", (1.95, 0.05)),
                _det("person", (-1.4, 1.1)), _det("bottle", (-1.35, 1.15)))  # fmt: skip
    assert [e.id for e in smap.entities("artifact")] == ["can_1"]
    people = smap.entities("person")
    assert [(e.id, round(e.position_in_world[0], 1)) for e in people] == [("person_1", -1.4)]


def test_a_person_beside_a_bench_hides_no_artifact_on_it_but_clothes_stay_dropped() -> None:
    """The wrist camera reads a bench's front as a person 25 cm in front of the can on it,
    outside the obstacle margin: the can, on the bench, is still mapped; an artifact
    detection on a person standing in the open is still dropped."""
    static = np.zeros((40, 40), np.uint8)
    static[18:22, 24:28] = OCCUPIED  # a bench: x 1.0–2.0, y −0.5–0.5
    smap = SemanticMap(SemanticMapSettings(), Occupancy(static, 0.25, (-5.0, -5.0)), {})
    for k in range(1, 4):
        _ingest(smap, k * S, _det("person", (0.8, 0.0)), _det("can", (1.1, 0.0)),
                _det("person", (-1.0, 1.0)), _det("box", (-1.0, 1.1)))  # fmt: skip
    assert [e.id for e in smap.entities("artifact")] == ["can_1"]
    assert len(smap.entities("person")) == 2


def test_one_object_seen_as_two_classes_keeps_one_id_and_deletes_the_other(
    tmp_path: Path,
) -> None:
    """A box from 3 m away (the network's far guess), then a can from 1.5 m at the same
    place: the box is deleted, with the reason, from the map and the database."""
    smap = _map()
    store = MapStore(tmp_path / "m.sqlite")
    far = msgspec.structs.replace(_det("box", CAN_XY), d_obj=3.0)
    reports = []
    for k in range(1, 6):
        reports.append(_ingest(smap, k * S, far))
        _commit(smap, store)
    for k in range(6, 9):
        reports.append(_ingest(smap, k * S, _det("can", CAN_XY)))
        _commit(smap, store)
    dropped = [d for r in reports for d in r.dropped]
    assert [i for i, _ in dropped] == ["box_1"]
    assert "the same object as can_1" in dropped[0][1]
    assert [e.id for e in smap.entities("artifact")] == ["can_1"]
    assert sorted(e.id for e, _app in store.load().entities) == ["can_1"]


def test_a_detection_cut_by_the_image_border_does_not_decide_the_class() -> None:
    smap = _map()
    cut = msgspec.structs.replace(
        _det("can", CAN_XY), bbox=(10, 0, 12, 2), mask=to_wire(np.ones((2, 2), np.uint8))
    )
    for k in range(1, 4):
        _ingest(smap, k * S, _det("box", CAN_XY))
        _ingest(smap, k * S + S // 2, cut)
    # The whole box views win; the cut can views, no evidence, never get an id.
    assert [e.id for e in smap.entities("artifact")] == ["box_1"]
    (can,) = [t for t in smap.artifacts.tracks if t.class_name == "can"]
    assert (can.id, can.hits, can.near_hits) == (None, 3, 0)


def test_a_person_on_the_robot_itself_is_not_fused() -> None:
    """The robot's own arm or leg read as a person: inside its footprint at capture (with
    a person's radius of margin) it is the robot; a person a step away is kept."""
    smap = _map()
    on_robot = _det("person", (0.3, 0.1))  # over the base, in front of the hips
    beside = _det("person", (0.0, 0.9))
    for k in range(1, 4):
        report = _ingest(smap, k * S, on_robot, beside)
        assert report.ignored >= 1
    people = [tr for tr in smap.tracks() if tr.class_name == "person"]
    assert len(people) == 1 and float(np.hypot(*(people[0].xy - (0.0, 0.9)))) < 0.2
