"""A map is of one place (its site): a database, a prior file or an import of another
site is refused with the reason and changes nothing; each world keeps its own database
by default (`database_path`); an old database without a site is taken and marked."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.bus import RequestError
from common.config import Config, SemanticMapSettings, load_config
from common.messages.semantic_map import MapFile
from services.semantic_map.exchange import check_import, export_map
from services.semantic_map.mapfile import write_map_file
from services.semantic_map.startup import MapSiteError, open_map
from services.semantic_map.store import MapStore, database_path

HALL_0, HALL_3 = "hall seed 0", "hall seed 3"


def _settings(tmp_path: Path, **kw: object) -> SemanticMapSettings:
    return msgspec.structs.replace(SemanticMapSettings(), dir=str(tmp_path), **kw)


def _no_world() -> None:
    return None


def test_the_site_is_the_simulated_world_unless_named_and_names_the_database(
    tmp_path: Path,
) -> None:
    config: Config = load_config({"sim.world_seed": 3})
    assert config.map_site() == HALL_3
    assert load_config({"semantic_map.site": "plant 7 bay B"}).map_site() == "plant 7 bay B"
    s = _settings(tmp_path)
    assert database_path(s, site=HALL_3) == tmp_path / "hall-seed-3.sqlite"
    assert database_path(s, site=HALL_0) != database_path(s, site=HALL_3)
    named = _settings(tmp_path, name="shop")
    assert database_path(named, site=HALL_3) == tmp_path / "shop.sqlite"
    assert database_path(s, "demo-1", site=HALL_3) == tmp_path / "demo-1.sqlite"


def test_a_database_of_another_site_is_refused_and_left_as_it_was(tmp_path: Path) -> None:
    s = _settings(tmp_path, start="empty", floor_plan="none", name="shared")
    path = database_path(s)
    store = MapStore(path)
    smap, how = open_map(s, store, _no_world, HALL_0)
    assert smap.site == HALL_0 and HALL_0 in how
    store.close()
    before = path.read_bytes()
    store = MapStore(path)
    with pytest.raises(MapSiteError, match="is a map of 'hall seed 0', and this stack is"):
        open_map(s, store, _no_world, HALL_3)
    store.close()
    assert path.read_bytes() == before
    store = MapStore(path)  # the same site resumes
    smap, how = open_map(s, store, _no_world, HALL_0)
    assert how.startswith("resumed") and smap.site == HALL_0
    assert export_map(smap).site == HALL_0
    store.close()


def test_a_database_from_before_sites_is_taken_and_marked_with_this_site(tmp_path: Path) -> None:
    s = _settings(tmp_path, start="empty", floor_plan="none", name="old")
    store = MapStore(database_path(s))
    open_map(s, store, _no_world, "")  # no site recorded
    assert store.load().meta["site"] == ""
    smap, _ = open_map(s, store, _no_world, HALL_3)
    assert smap.site == HALL_3 and store.load().meta["site"] == HALL_3
    store.close()


def test_a_prior_file_or_an_import_of_another_site_is_refused(tmp_path: Path) -> None:
    prior = tmp_path / "prior.json"
    write_map_file(prior, MapFile(site=HALL_0))
    s = _settings(tmp_path, start="prior", prior_file=str(prior), floor_plan="none")
    store = MapStore(database_path(s, site=HALL_3))
    with pytest.raises(MapSiteError, match="prior map file"):
        open_map(s, store, _no_world, HALL_3)
    assert store.is_empty()
    smap, _ = open_map(s, store, _no_world, HALL_0)
    assert smap.site == HALL_0
    store.close()
    with pytest.raises(RequestError, match="is a map of 'hall seed 0'") as err:
        check_import(MapFile(site=HALL_0), HALL_3)
    assert err.value.code == "invalid"
    check_import(MapFile(site=HALL_3), HALL_3)
    with pytest.raises(RequestError, match="names no site"):
        check_import(MapFile(), HALL_3)  # a file that does not say which world it maps


def test_a_map_on_the_floor_plan_judges_artifacts_against_its_tables_tops(
    tmp_path: Path,
) -> None:
    """With the floor plan (the truth ablation's static layer), the plan's tables and
    benches are the map's surfaces, as an explored map's are: a detection at table_1's
    edge at its top's height is the table itself (hall seed 1's shift: nine false
    bottles and boxes along that table's edges, each walked to), one above it stands on
    it; the surfaces stay with the database."""
    from common.messages.world import WorldDescription
    from services.semantic_map.evidence import artifact_doubt
    from services.sim.world import generate_world

    world: WorldDescription = generate_world(1)
    s = _settings(tmp_path, start="empty", floor_plan="world", name="plan")
    store = MapStore(database_path(s))
    smap, _ = open_map(s, store, lambda: world, "hall seed 1")
    assert smap.surfaces == list(world.surfaces)
    table = next(t for t in smap.surfaces if t.id == "table_1")
    edge = np.array([1.85, -2.07])  # bottle_8 of the shift, at the table's front edge
    assert "the surface itself" in artifact_doubt(edge, table.top_height - 0.01, smap.surfaces)
    assert artifact_doubt(edge, table.top_height + 0.1, smap.surfaces) == ""
    store.close()
    store = MapStore(database_path(s))
    again, how = open_map(s, store, lambda: world, "hall seed 1")
    assert how.startswith("resumed") and again.surfaces == smap.surfaces
    store.close()


def test_a_resumed_map_still_forgets_what_stood_on_the_floor_and_went(tmp_path: Path) -> None:
    """The learned layer's lowest hits go with the database, so a restarted map clears a
    cell a person left as the running one would (`Occupancy._clear`)."""
    from services.semantic_map.commit import learned_grids
    from services.semantic_map.occupancy import CLEAR_FRAMES, OCCUPIED
    from services.sim.world import generate_world

    world = generate_world(0, "small")
    s = _settings(tmp_path, start="empty", floor_plan="world", name="low")
    store = MapStore(database_path(s))
    smap, _ = open_map(s, store, lambda: world, "small seed 0")
    occ = smap.occupancy
    ix, iy, _ = occ.cells_of(np.array([[0.52, 0.52]]))
    res = occ.resolution_m
    x, y = (occ.origin_xy[k] + (float(i[0]) + 0.5) * res for k, i in ((0, ix), (1, iy)))
    legs = np.array([[x, y, 0.3], [x, y, 0.6]])  # a person the detector missed
    for _ in range(occ.hits_needed):
        occ.integrate(legs)
    assert occ.cells()[iy, ix] == OCCUPIED
    store.commit(grids=learned_grids(occ))
    store.close()
    store = MapStore(database_path(s))
    again, how = open_map(s, store, lambda: world, "small seed 0")
    assert how.startswith("resumed") and again.occupancy.cells()[iy, ix] == OCCUPIED
    for _ in range(CLEAR_FRAMES):
        again.occupancy.integrate(np.array([[x, y, 0.01]]))  # they went: floor there
    assert again.occupancy.cells()[iy, ix] != OCCUPIED
    store.close()
