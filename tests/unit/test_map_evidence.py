"""The map's own geometry against false entries (`services.semantic_map.evidence`): the
cases the explored small world showed (boxes flat on a table top, bottles under it, a
"person" in the table, one beyond the walls, bottles on a person), as pure rules and
through the mapper's frames."""

from __future__ import annotations

import numpy as np

from common.config import SemanticMapSettings
from common.geometry import make_T
from common.messages.perception import Detection, Detections
from common.messages.world import SupportSurface
from common.robot_description import R_FORWARD_OPTICAL
from services.semantic_map.entities import Track
from services.semantic_map.evidence import (
    artifact_doubt,
    known_floor_near,
    on_obstacle,
    person_doubt,
    surface_under,
)
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import FREE, OCCUPIED, UNKNOWN, Occupancy
from tests.unit.map_fakes import detection

S = 1_000_000_000
#: A table 1.4 x 0.8 m at (2, 0), top at 0.8 m, turned 90°.
TABLE = SupportSurface("surface_1", (2.0, 0.0), (0.7, 0.4), np.pi / 2, 0.8)


def test_an_artifact_over_a_surface_stands_on_its_top() -> None:
    assert surface_under(np.array([2.3, 0.6]), [TABLE]) is TABLE  # along the turned length
    assert surface_under(np.array([2.6, 0.0]), [TABLE]) is None  # beyond its width
    assert artifact_doubt(np.array([2.0, 0.3]), 0.87, [TABLE]) == ""  # a box 8 cm tall
    assert artifact_doubt(np.array([2.0, 0.3]), 0.91, [TABLE]) == ""  # a bottle
    flat = artifact_doubt(np.array([2.0, 0.3]), 0.82, [TABLE])
    assert flat.startswith("flat on the top of surface_1")
    assert artifact_doubt(np.array([2.0, 0.3]), 0.62, [TABLE]).startswith("below the top")
    assert "taller than any artifact" in artifact_doubt(np.array([2.0, 0.3]), 1.4, [TABLE])
    assert artifact_doubt(np.array([5.0, 0.0]), 0.2, [TABLE]) == ""  # off every surface: no say


def test_an_artifact_at_a_tops_height_just_off_its_rectangle_is_the_tops_edge() -> None:
    """Seed 1's shift: the network read table_1's long edges as bottles and boxes, their
    centroids 1-2 cm below the top; an explored top's rectangle can stop short of that
    edge. Off the rectangle, a real object stands on the floor or on the top, above it."""
    beyond = np.array([2.55, 0.0])  # 0.15 m beyond the turned table's width
    edge = artifact_doubt(beyond, 0.785, [TABLE])
    assert edge.startswith("at the edge of surface_1's top (0.80 m) at 0.79 m"), edge
    assert artifact_doubt(beyond, 0.7, [TABLE]).startswith("at the edge")  # its apron
    assert artifact_doubt(beyond, 0.82, [TABLE]) == ""  # a box on the top, past the rectangle
    assert artifact_doubt(beyond, 0.12, [TABLE]) == ""  # a bottle on the floor beside it
    assert artifact_doubt(np.array([2.65, 0.0]), 0.785, [TABLE]) == ""  # 0.25 m off: no say


def _floor_map() -> Occupancy:
    """A 4 x 4 m room: free inside, a wall at x = 1.5 m, unknown beyond it."""
    cells = np.full((80, 80), UNKNOWN, np.uint8)
    cells[:, :70] = FREE
    cells[:, 70:72] = OCCUPIED
    occ = Occupancy(cells, 0.05, (-2.0, -2.0))
    occ.sensed_static()
    return occ


def test_an_artifact_off_every_surface_stands_on_the_floor_or_on_a_top() -> None:
    occ = _floor_map()
    wall_end = np.array([-1.0, -1.0])  # free floor round it, nothing to stand on
    assert artifact_doubt(wall_end, 0.27, [], occ).startswith("on no surface, 0.27 m over")
    assert artifact_doubt(wall_end, 0.12, [], occ) == ""  # a bottle on the floor
    assert artifact_doubt(wall_end, 0.27, [], None) == ""  # no grid: no say
    occ.top_z[18:22, 18:22], occ.top_n[18:22, 18:22] = 0.7, 4  # a table top seen there
    assert artifact_doubt(wall_end, 0.8, [], occ) == ""
    occ.top_n[18:22, 18:22] = 0
    occ.static[20, 21] = OCCUPIED  # a wall's end in the next cell: it still floats
    assert artifact_doubt(wall_end, 0.3, [], occ).startswith("on no surface")
    occ.static[20, 20] = OCCUPIED  # something under it that is not floor
    assert artifact_doubt(wall_end, 0.3, [], occ) == ""


def test_a_person_stands_on_floor_and_not_in_a_table() -> None:
    occ = _floor_map()
    assert known_floor_near(occ, np.array([0.0, 0.0]), 0.35)
    assert not known_floor_near(occ, np.array([1.95, 0.0]), 0.35)  # 0.4 m behind the wall
    assert person_doubt(np.array([0.0, 0.0]), [TABLE], occ) == ""
    assert person_doubt(np.array([1.95, 0.0]), [], occ).startswith("no floor the map knows")
    assert person_doubt(np.array([1.95, 0.0]), [], None) == ""  # a floor plan's map: no say
    assert person_doubt(np.array([2.1, 0.2]), [TABLE], None) == "inside the top of surface_1"


def test_a_person_inside_an_obstacle_the_depth_learned_is_none() -> None:
    """The small world explored: a "person" made of a table's underside, 0.3 m inside the
    table's footprint the depth had learned, whose top the tops layer never saw."""
    occ = _floor_map()
    occ.hits[36:50, 36:50] = occ.hits_needed  # a table's footprint, 0.7 m square at 0-0.7
    inside = person_doubt(np.array([0.17, 0.17]), [], occ)
    assert inside == "inside an obstacle the map knows (every cell within 0.1 m)"
    assert person_doubt(np.array([-0.18, 0.17]), [], occ) == ""  # at its edge: beside it
    assert person_doubt(np.array([0.17, 0.17]), [], None) == ""  # a floor plan's map: no say
    assert on_obstacle(occ, np.array([0.17, 0.17]))
    assert not on_obstacle(occ, np.array([-1.0, -1.0]))


# -- through the mapper ---------------------------------------------------------------------

W, H = 320, 240
T_BASE_CAMERA = make_T(R_FORWARD_OPTICAL, (0.0, 0.0, 0.8))


def _ingest(smap: SemanticMap, t: int, *dets: Detection) -> int:
    msg = Detections(
        stamp_ns=t,
        camera="camera_head",
        T_world_base=tuple(np.eye(4).ravel().tolist()),
        segmenter="network",
        detections=list(dets),
    )
    return smap.ingest(msg).ignored


def _explored_map() -> SemanticMap:
    occ = _floor_map()
    # the table's top edge as the tops layer has it, seen from the side (x 0.5-1.1 m)
    occ.top_z[30:50, 50:62], occ.top_n[30:50, 50:62] = 0.78, 5
    smap = SemanticMap(SemanticMapSettings(floor_plan="none"), occ, {})
    smap.static_source = "slam"
    t = TABLE  # the same table, in the room: at (0.8, 0)
    smap.surfaces = [SupportSurface(t.id, (0.8, 0.0), t.half_extents, t.yaw, t.top_height)]
    return smap


def test_the_mapper_ignores_what_cannot_be_and_keeps_what_can() -> None:
    smap = _explored_map()
    for k in range(6):
        t = (k + 1) * S // 10
        ignored = _ingest(
            smap,
            t,
            detection("bottle", 0.8, 0.2, 0.9),  # on the table
            detection("box", 0.8, -0.2, 0.81),  # the table's top read as a box
            detection("can", 0.9, 0.0, 0.55),  # under it: its legs
            detection("person", 0.8, 0.1, 1.0),  # in it
            detection("person", 1.9, 0.5, 1.0),  # beyond the wall
            detection("person", -1.0, 1.0, 1.0),  # on the floor
        )
        assert ignored == 4
    assert [t.class_name for t in smap.artifacts.confirmed] == ["bottle"]
    assert len(smap.people.confirmed) == 1
    # a bottle in the person's hand: off every surface and within reach of them
    for k in range(6):
        _ingest(smap, S + k * S // 10, detection("bottle", -1.0, 1.45, 1.0))
    assert [t.class_name for t in smap.artifacts.confirmed] == ["bottle"]


def test_entries_the_map_made_are_deleted_once_its_surfaces_say_they_cannot_be() -> None:
    smap = _explored_map()
    surfaces, smap.surfaces = smap.surfaces, []  # made before the table was seen from above

    def track(name: str, xy: tuple[float, float], z: float, source: str = "perception") -> str:
        cls = name.split("_")[0]
        kind = "person" if cls == "person" else "artifact"
        smap.add(Track(cls, kind, np.array(xy), np.eye(2) * 0.01, z, source, id=name))  # type: ignore[arg-type]
        return name

    box = track("box_1", (0.8, -0.2), 0.81)
    bottle = track("bottle_1", (0.8, 0.2), 0.9)
    seated = track("person_1", (0.8, 0.1), 0.0)
    prior = track("can_1", (0.9, 0.0), 0.55, "prior")  # another run's: not for this one to judge
    assert smap.drop_doubtful() == []
    smap.surfaces = surfaces
    dropped = dict(smap.drop_doubtful())
    assert set(dropped) == {box, seated}
    assert dropped[box].startswith("not where a box can be: flat on the top of surface_1")
    assert dropped[seated] == "not where a person can be: inside the top of surface_1"
    assert {t.id for t in smap.tracks()} == {bottle, prior}
    assert set(smap.take_deletions()) == {box, seated}


def test_a_person_made_before_the_lidar_mapped_a_machine_face_is_deleted_once_it_has() -> None:
    """The network reads a machine's edges as a person, the centroid on its face: seen
    before the SLAM grid had that face, the "person" is kept; once the grid has it, gone.
    A person standing 0.3 m from the machine stays."""
    smap = _explored_map()
    phantom, worker = "person_1", "person_2"
    for name, xy in ((phantom, (-0.98, -1.0)), (worker, (-1.3, 0.6))):
        smap.add(Track("person", "person", np.array(xy), np.eye(2) * 0.01, 0.0, "perception", name))
    assert smap.drop_doubtful() == []
    cells = smap.occupancy.static.copy()
    machine = (slice(16, 52), slice(21, 36))  # x -0.95..-0.2, y -1.2..0.6: the worker 0.35 m off
    cells[machine] = OCCUPIED
    smap.occupancy.adopt_static(cells)
    dropped = dict(smap.drop_doubtful())
    assert set(dropped) == {phantom}
    assert "static obstacle" in dropped[phantom]
    assert [t.id for t in smap.people.confirmed] == [worker]


def test_only_a_person_the_map_would_keep_makes_an_artifact_off_every_top_their_hand() -> None:
    """Hall seed 1 explored: box_2 stood 0.1 m inside table_2's edge, off the explored
    top (short of that edge), on the table's occupied cells; a "person" of 4 wrist-camera
    detections 4 cm from it deleted it, and was itself deleted as a false entry 14 s
    later. A person of so few detections is no evidence; one seen often is, for an
    artifact over free floor; on the table's cells the box stands on the table."""
    smap = _explored_map()
    smap.occupancy.static[40:44, 64:68] = OCCUPIED  # under the box: the table's edge
    box = Track("box", "artifact", np.array([1.3, 0.0]), np.eye(2) * 0.01, 0.8, "perception",
                id="box_1", hits=30)  # fmt: skip
    smap.add(box)
    person = Track("person", "person", np.array([1.3, 0.04]), np.eye(2) * 0.01, 0.0,
                   "perception", id="person_1", hits=4)  # fmt: skip
    person.last_seen_ns = smap.stamp_ns
    smap.add(person)
    assert smap._doubt_artifact(box.xy, box.z, smap.stamp_ns) == ""
    person.hits = 10
    assert smap._doubt_artifact(box.xy, box.z, smap.stamp_ns) == "", "on the table's cells"
    held = np.array([1.3, 0.3])  # over free floor beside them: in their hand
    assert smap._doubt_artifact(held, 0.8, smap.stamp_ns) == "on no surface, 0.26 m from person_1"
