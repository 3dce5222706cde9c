"""The surfaces artifacts stand on, as the map sees them with no floor plan
(`services.semantic_map.supports.surfaces_from_tops` on the occupancy's tops layer): a
bench top seen in a few frames is one surface with its place, size, yaw and height; a
wall, a low pallet and a top seen once are none; the front edge of a bench top the head
camera sees from below is a strip there; the surfaces survive the database and a map file."""

from __future__ import annotations

import math
from pathlib import Path

import msgspec
import numpy as np

from common.config import SemanticMapSettings
from common.messages.world import SupportSurface
from services.semantic_map.exchange import export_map
from services.semantic_map.mapfile import write_map_file
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.startup import open_map, save_all
from services.semantic_map.store import MapStore
from services.semantic_map.supports import surfaces_from_tops, with_kept

RES = 0.05


def occupancy() -> Occupancy:
    return Occupancy.unknown(5.0, RES, hits_needed=2)


def top(cx: float, cy: float, half: tuple[float, float], yaw: float, z: float) -> np.ndarray:
    """Points every 2 cm on a rectangle at height z (a table's top seen from above)."""
    u, v = np.meshgrid(np.arange(-half[0], half[0], 0.02), np.arange(-half[1], half[1], 0.02))
    c, s = math.cos(yaw), math.sin(yaw)
    x, y = cx + c * u - s * v, cy + s * u + c * v
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


def wall(x: float, y0: float, y1: float, z_max: float) -> np.ndarray:
    y, z = np.meshgrid(np.arange(y0, y1, 0.02), np.arange(0.2, z_max, 0.05))
    return np.column_stack([np.full(y.size, x), y.ravel(), z.ravel()])


def test_a_bench_top_is_one_surface_and_a_wall_a_pallet_and_one_glance_are_none() -> None:
    occ = occupancy()
    bench = top(1.0, 2.0, (0.8, 0.35), math.radians(30.0), 0.9)
    pallet = top(-2.0, -2.0, (0.6, 0.4), 0.0, 0.15)
    for z_max in (1.1, 1.5, 1.9):  # a wall seen higher up as the robot backs off
        occ.integrate(np.concatenate([bench, pallet, wall(-4.0, -3.0, 3.0, z_max)]))
    occ.integrate(top(3.0, -3.0, (0.3, 0.3), 0.0, 0.75))  # a top seen once
    found = surfaces_from_tops(occ.top_z, occ.top_n, occ.resolution_m, occ.origin_xy)
    assert len(found) == 1
    s = found[0]
    assert s.id == "surface_1"
    assert math.hypot(s.centre_xy[0] - 1.0, s.centre_xy[1] - 2.0) < 0.05
    assert abs(s.top_height - 0.9) < 0.01
    long_, short = sorted(s.half_extents, reverse=True)
    assert abs(long_ - 0.8) < 0.06 and abs(short - 0.35) < 0.06
    axis = s.yaw if s.half_extents[0] >= s.half_extents[1] else s.yaw + math.pi / 2
    assert abs(math.sin(axis - math.radians(30.0))) < 0.05


def test_a_top_counts_only_where_the_frame_saw_over_it() -> None:
    """Frames that see a wall and a standing person only up to about 1.1 m, where their
    picture ends: neither has a top, so neither is a surface; the bench in the same
    frames, seen over, still is one. Without the test, three."""
    occ = occupancy()
    bench = top(1.0, 2.0, (0.8, 0.35), 0.0, 0.9)
    near_wall = wall(-4.0, -3.0, 3.0, 1.1)  # seen to 1.05 m
    person = top(-1.0, -1.0, (0.15, 0.1), 0.0, 1.08)  # a body's column, seen to 1.08 m

    def in_the_picture(p: np.ndarray) -> np.ndarray:
        return np.asarray(p[:, 2] < 1.07)  # nothing in front of what it sees

    for _ in range(5):
        occ.integrate(np.concatenate([bench, near_wall, person]), in_the_picture)
    found = surfaces_from_tops(occ.top_z, occ.top_n, occ.resolution_m, occ.origin_xy)
    assert [round(s.top_height, 2) for s in found] == [0.9]
    blind = occupancy()
    for _ in range(5):
        blind.integrate(np.concatenate([bench, near_wall, person]))
    assert len(surfaces_from_tops(blind.top_z, blind.top_n, RES, blind.origin_xy)) == 3


def test_the_front_edge_seen_from_below_is_a_strip_there() -> None:
    occ = occupancy()
    edge = top(0.0, 1.0, (0.8, 0.02), 0.0, 0.9)  # the head camera sees only the edge
    for _ in range(3):
        occ.integrate(edge)
    (s,) = surfaces_from_tops(occ.top_z, occ.top_n, occ.resolution_m, occ.origin_xy)
    assert math.hypot(s.centre_xy[0], s.centre_xy[1] - 1.0) < 0.05
    assert max(s.half_extents) > 0.75


def test_the_surfaces_survive_the_database_and_the_map_file(tmp_path: Path) -> None:
    s = SemanticMapSettings(floor_plan="none", grid_half_extent_m=5.0)
    occ = occupancy()
    for _ in range(3):
        occ.integrate(top(1.0, 2.0, (0.8, 0.35), 0.0, 0.9))
    smap = SemanticMap(s, occ, {})
    smap.find_surfaces()
    assert len(smap.surfaces) == 1
    assert export_map(smap).supports == smap.surfaces
    path = tmp_path / "m.sqlite"
    store = MapStore(path)
    save_all(smap, store, {"start": "empty", "static_source": "slam"})
    store.close()
    again, _how = open_map(s, MapStore(path), lambda: None)
    assert again.surfaces == smap.surfaces
    assert again.static_source == "slam"
    assert np.array_equal(again.occupancy.top_n, smap.occupancy.top_n)
    again.find_surfaces()
    assert again.surfaces == smap.surfaces


def test_a_map_started_from_a_file_serves_its_supports_until_this_run_sees_them(
    tmp_path: Path,
) -> None:
    s = SemanticMapSettings(floor_plan="none", grid_half_extent_m=5.0)
    occ = occupancy()
    for _ in range(3):
        occ.integrate(top(1.0, 2.0, (0.8, 0.35), 0.0, 0.9))
        occ.integrate(top(-2.0, -1.0, (0.5, 0.3), 0.0, 0.75))
    explored = SemanticMap(s, occ, {})
    explored.find_surfaces()
    assert len(explored.surfaces) == 2
    path = tmp_path / "saved.json"
    write_map_file(path, export_map(explored))

    prior = msgspec.structs.replace(s, start="prior", prior_file=str(path))
    smap, _how = open_map(prior, MapStore(tmp_path / "m.sqlite"), lambda: None)
    assert smap.surfaces == explored.surfaces and smap.static_source == "file"
    smap.find_surfaces()  # no tops yet: the file's
    assert smap.surfaces == explored.surfaces
    for _ in range(3):  # this run sees the first table, a little off: its own, and the other
        smap.occupancy.integrate(top(1.02, 2.0, (0.8, 0.35), 0.0, 0.9))
    smap.find_surfaces()
    assert [round(x.top_height, 2) for x in smap.surfaces] == [0.75, 0.9]
    assert [x.id for x in smap.surfaces] == ["surface_1", "surface_2"]
    assert abs(smap.surfaces[1].centre_xy[0] - 1.02) < 0.03  # this run's, not the file's


def test_kept_surfaces_give_way_to_any_found_over_them() -> None:
    def surface(x: float, y: float, half: float) -> SupportSurface:
        return SupportSurface("", (x, y), (half, half), 0.0, 0.8)

    kept = [surface(0.0, 0.0, 0.5), surface(3.0, 0.0, 0.5), surface(6.0, 0.0, 0.1)]
    found = [surface(0.3, 0.3, 0.5), surface(6.05, 0.0, 1.0)]  # over the 1st and the 3rd
    out = with_kept(found, kept)
    assert [x.centre_xy for x in out] == [(0.3, 0.3), (3.0, 0.0), (6.05, 0.0)]
    assert [x.id for x in out] == ["surface_1", "surface_2", "surface_3"]
    assert with_kept(found, []) == found


def _wall_face(occ: Occupancy) -> np.ndarray:
    """A lidar map of free floor with a wall's face at x = 1.0–1.05 (column 60)."""
    static = np.full(occ.static.shape, 0, np.uint8)
    static[:, 60] = 100
    return static


def test_beside_a_lidar_wall_the_depth_learns_nothing_elsewhere_it_does() -> None:
    """The depth's noise spreads a wall's face over two cells; the lidar's map already has
    it: on a sensed static layer the learned cell inside is not added, a table top the
    lidar's plane misses is."""
    occ = Occupancy.unknown(2.0, RES, hits_needed=2)
    static = _wall_face(occ)
    occ.adopt_static(static)
    face = np.column_stack([np.full(20, 0.97), np.linspace(-0.5, 0.5, 20), np.full(20, 1.0)])
    table = top(-1.0, 0.0, (0.3, 0.2), 0.0, 0.75)
    for _ in range(3):
        occ.integrate(np.concatenate([face, table]))
    cells = occ.cells()
    assert (cells[:, 59] == 100).sum() == 0  # x 0.95–1.0: beside the wall
    assert (cells == 100).sum() > static.astype(bool).sum() + 100  # the table was learned


def test_on_a_sensed_layer_the_depth_leaves_walls_to_the_lidar_but_learns_tables() -> None:
    """The explored small world's settings: 12 frames, nothing within 0.2 m of a wall or a
    machine; a table's legs are small blobs: the top above and beside them is learned."""
    occ = Occupancy.unknown(2.0, RES, hits_needed=3, sensed=(12, 0.2))
    static = _wall_face(occ)
    for lx, ly in ((-1.3, -0.2), (-1.3, 0.15), (-0.75, -0.2), (-0.75, 0.15)):  # 4 legs
        static[int((ly + 2.0) / RES), int((lx + 2.0) / RES)] = 100
    occ.adopt_static(static)
    ghost = np.column_stack([np.full(20, 0.87), np.linspace(-0.5, 0.5, 20), np.full(20, 1.0)])
    table = top(-1.0, 0.0, (0.3, 0.2), 0.0, 0.75)
    for k in range(12):
        occ.integrate(np.concatenate([ghost, table]))
        learned = occ.learned_mask()
        assert learned.any() == (k == 11)  # not before the 12th frame
    assert not learned[:, 55:60].any()  # the wall's face painted 15 cm in front: the lidar's
    leg = (int((-0.2 + 2.0) / RES), int((-1.3 + 2.0) / RES))
    assert learned[leg[0] + 1, leg[1] + 1]  # the top beside a leg
    assert learned.sum() >= 90  # the whole top (0.6 x 0.4 m: 96 cells), but the legs


def test_a_mapped_person_standing_leaves_no_obstacle_in_the_lidar_map() -> None:
    """The SLAM grid holds a blob where a person stood: with that person mapped there the
    blob is theirs (unknown), while a pillar's blob nobody stands at and a bench beside
    the person stay obstacles."""
    occ = Occupancy.unknown(2.0, RES)
    static = np.zeros(occ.static.shape, np.uint8)
    static[40:48, 40:48] = 100  # a person's blob at x, y 0.0–0.4
    static[10:16, 10:16] = 100  # a pillar at −1.5
    static[40:48, 50:80] = 100  # a bench from x 0.5, 1.5 m long
    occ.adopt_static(static, people=np.array([[0.2, 0.2]]))
    assert (occ.static[40:48, 40:48] == 255).all()
    assert (occ.static[10:16, 10:16] == 100).all()
    assert (occ.static[40:48, 50:80] == 100).all()


def _person_blob_map(s: SemanticMapSettings) -> SemanticMap:
    """A SLAM map (as saved after its last grid was taken) holding a standing person's
    blob at x, y 0.0-0.4 with that person mapped there, a pillar's blob and a bench."""
    from services.semantic_map.entities import Track

    occ = Occupancy.unknown(s.grid_half_extent_m, RES)
    static = np.zeros(occ.static.shape, np.uint8)
    c = round(s.grid_half_extent_m / RES)  # the cell of x, y = 0
    static[c : c + 8, c : c + 8] = 100  # the person's blob
    static[c - 30 : c - 24, c - 30 : c - 24] = 100  # a pillar 1.5 m off
    static[c : c + 8, c + 10 : c + 40] = 100  # a bench from x 0.5, 1.5 m long
    occ.static[:] = static
    occ.static_occupied = static == 100
    smap = SemanticMap(s, occ, {})
    smap.static_source = "slam"
    smap.add(Track(class_name="person", kind="person", xy=np.array([0.2, 0.2]),
                   cov=np.eye(2) * 1e-2, z=0.0, source="perception", id="person_1"))  # fmt: skip
    return smap


def test_a_saved_lidar_map_read_back_leaves_out_the_blob_of_a_person_it_has(
    tmp_path: Path,
) -> None:
    """Resumed from its database, or started from its file, the map's static layer has the
    person's blob unknown (the lidar's protective field then sees their legs there), the
    pillar and the bench as they were."""
    s = SemanticMapSettings(floor_plan="none", grid_half_extent_m=2.0)
    c = round(2.0 / RES)
    store = MapStore(tmp_path / "m.sqlite")
    save_all(_person_blob_map(s), store, {"start": "empty", "static_source": "slam"})
    store.close()
    write_map_file(tmp_path / "saved.json", export_map(_person_blob_map(s)))
    prior = msgspec.structs.replace(s, start="prior", prior_file=str(tmp_path / "saved.json"))
    for how, got in (
        ("resumed", open_map(s, MapStore(tmp_path / "m.sqlite"), lambda: None)[0]),
        ("from its file", open_map(prior, MapStore(tmp_path / "p.sqlite"), lambda: None)[0]),
    ):
        static = got.occupancy.static
        assert (static[c : c + 8, c : c + 8] == 255).all(), how
        assert (static[c - 30 : c - 24, c - 30 : c - 24] == 100).all(), how
        assert (static[c : c + 8, c + 10 : c + 40] == 100).all(), how
        assert not got.occupancy.furniture[c : c + 8, c : c + 8].any(), how
        assert got.occupancy.furniture[c : c + 8, c + 10 : c + 40].all(), how


def test_forgetting_people_changes_nothing_where_nobody_is_mapped() -> None:
    s = SemanticMapSettings(floor_plan="none", grid_half_extent_m=2.0)
    smap = _person_blob_map(s)
    before, version = smap.occupancy.static.copy(), smap.occupancy.version
    assert smap.occupancy.forget_people(np.array([[-1.0, 1.0]])) == 0
    assert np.array_equal(smap.occupancy.static, before) and smap.occupancy.version == version
    assert smap.occupancy.forget_people(np.array([[0.25, 0.1]])) == 64
    assert smap.occupancy.version == version + 1
