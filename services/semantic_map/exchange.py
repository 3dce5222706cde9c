"""The whole map in and out as a `MapFile`: `dume/map/export` and `dume/map/import`.

`check_import(mf)` refuses a file the map cannot take with `RequestError("invalid", why)`
(of another site or of none, an id named twice, an entity whose kind and class
disagree) before anything changes; so does `import_map` for a grid it cannot take.
`import_map(mf, smap, store, views)` then replaces the map with the file's: its entities
(source `import`), id counters and, when it has one, its occupancy grid as the static
layer; writes the whole map in one SQLite transaction (`startup.save_all`); leaves the
map's view of now as the only one (`ViewHistory.restart`); answers the `MapSummary`.
`export_map(smap)` is the map now as a file. The node calls `check_import` on the
queryable's thread without the map's lock, and the others with it held.
"""

from __future__ import annotations

import logging

from common.bus import RequestError
from common.messages.semantic_map import MapFile, MapSummary
from services.semantic_map.mapfile import occupancy_from_grid, tracks_from_file
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.startup import MapSiteError, check_site, save_all
from services.semantic_map.store import MapStore
from services.semantic_map.views import ViewHistory

log = logging.getLogger("dume.semantic_map")


def check_import(mf: MapFile, site: str = "") -> None:
    """Refuse (`RequestError`, code `invalid`) a file the map cannot take: one of
    another site than `site` or of none (a file that does not say which world it maps
    is not taken over a stack's map: `dume trial fuzz` wiped the map with such files),
    or inconsistent."""
    if site and not mf.site:
        raise RequestError("invalid", f"the file names no site; this stack is {site!r}")
    try:
        check_site("the file", mf.site, site)
    except MapSiteError as exc:
        raise RequestError("invalid", str(exc)) from None
    ids = [e.id for e in mf.entities]
    if len(set(ids)) != len(ids):
        raise RequestError("invalid", "the map file names an id twice")
    bad = [e.id for e in mf.entities if (e.kind == "person") != (e.class_name == "person")]
    if bad:
        raise RequestError("invalid", f"kind and class disagree for {bad}")


def import_map(mf: MapFile, smap: SemanticMap, store: MapStore, views: ViewHistory) -> MapSummary:
    """Replace the map and its database with the (checked) file's map. Everything is
    built from the file first: one that fails (`RequestError` invalid) changes nothing
    (a grid of the wrong dtype once failed after the map was cleared)."""
    occupancy = None
    try:
        if mf.occupancy is not None:
            occ = smap.occupancy
            occupancy = occupancy_from_grid(
                mf.occupancy, hits_needed=occ.hits_needed, z_range=occ.z_range, sensed=occ.sensed
            )
            occupancy.sensed_static()
        tracks = tracks_from_file(mf, "import")
    except ValueError as exc:
        raise RequestError("invalid", f"the map file cannot be taken: {exc}") from None
    smap.clear()
    smap.ids.counters.update(mf.counters)
    if occupancy is not None:
        smap.occupancy = occupancy
        smap.static_source = "file"
    smap.surfaces = smap.surfaces_before = list(mf.supports)
    for tr in tracks:
        smap.add(tr)
    smap.forget_people_in_static()
    save_all(smap, store, {"static_source": smap.static_source})
    views.restart(smap)
    log.info("imported a map: %d entities", len(mf.entities))
    return summary(smap)


def summary(smap: SemanticMap) -> MapSummary:
    arts = smap.entities("artifact")
    return MapSummary(
        stamp_ns=smap.stamp_ns,
        artifacts=len(arts),
        people=len(smap.people.confirmed),
        missing=sum(e.missing_since_ns is not None for e in arts),
    )


def export_map(smap: SemanticMap) -> MapFile:
    entities = smap.entities("artifact") + smap.entities("person")
    return MapFile(
        stamp_ns=smap.stamp_ns,
        site=smap.site,
        entities=entities,
        counters=dict(smap.ids.counters),
        occupancy=smap.grid(),
        supports=list(smap.surfaces),
        appearances={
            t.id: [round(float(v), 5) for v in t.appearance]
            for t in smap.people.confirmed
            if t.id is not None and t.appearance is not None
        },
    )
