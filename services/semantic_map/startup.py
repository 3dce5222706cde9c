"""Opening a map: resume the database, or fill an empty one per `semantic_map.start`.

A database that holds a map is resumed (entities with their ids and histograms, the id
counters, the static and learned occupancy layers) whatever the start mode, unless
`reset`. An empty one starts from a prior map file, from the sim's truth with noise, or
empty; the static layer comes from the file, or else from the floor plan (the sim's grid)
when `floor_plan = "world"`, or is unknown. Every map records its site (`Config.map_site`:
which place it is of); a database or prior file of another site is refused
(`MapSiteError`), never silently used. `world_description` asks the sim for its
world (what `open_map` and the floor plan's supports, `supports`, read), waiting a
bounded time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Literal

import msgspec
import numpy as np

from common.bus import Bus, NoReply, RemoteError
from common.config import SemanticMapSettings, resolve
from common.keys import WORLD_DESCRIPTION
from common.messages import PayloadError
from common.messages.world import SupportSurface, WorldDescription
from services.semantic_map.commit import learned_grids, surfaces_json
from services.semantic_map.entities import Track
from services.semantic_map.mapfile import (
    occupancy_from_grid,
    occupancy_from_world,
    read_map_file,
    seed_from_world,
    tracks_from_file,
)
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.store import Grid, MapStore

log = logging.getLogger(__name__)
_SURFACES = msgspec.json.Decoder(list[SupportSurface])
#: The service's logger (its lines go to rerun too), for the wait for the world.
service_log = logging.getLogger("dume.semantic_map")


def world_description(
    bus: Bus, stop: threading.Event, wait_s: float = 30.0
) -> WorldDescription | None:
    """The sim's world description (`dume/world/description`), asked for again every 0.5 s
    until it answers, `stop` is set or `wait_s` wall seconds passed (then None)."""
    deadline = time.monotonic() + wait_s
    while not stop.is_set() and time.monotonic() < deadline:
        try:
            return bus.query(WORLD_DESCRIPTION, None, WorldDescription, 5.0)
        except (NoReply, RemoteError, PayloadError) as exc:
            service_log.info("waiting for the world description: %s", exc)
            time.sleep(0.5)
    return None


class MapSiteError(ValueError):
    """A map of another place than this stack's: which, and what to do."""


def check_site(what: str, recorded: str, site: str) -> None:
    """`MapSiteError` when `what` (a database, a file) records a site other than `site`
    (one recording none, from before sites were kept, is taken)."""
    if recorded and site and recorded != site:
        raise MapSiteError(
            f"{what} is a map of {recorded!r}, and this stack is {site!r}: give a map of "
            f"{site!r} (or semantic_map.name for a new database; semantic_map.reset=true "
            "starts this one over)"
        )


def open_map(
    s: SemanticMapSettings,
    store: MapStore,
    world: Callable[[], WorldDescription | None],
    site: str = "",
) -> tuple[SemanticMap, str]:
    """The map and a sentence saying where it came from. `world()` fetches the sim's
    description (None when there is none); it is called only when needed. `site`: the
    place the map must be of (`MapSiteError` otherwise)."""
    occ_kw = dict(
        hits_needed=s.obstacle_hits,
        z_range=tuple(s.obstacle_z_m),
        sensed=(s.obstacle_hits_sensed, s.sensed_clearance_m),
    )
    if not store.is_empty():
        return _resume(s, store, occ_kw, site)
    tracks: list[Track] = []
    occ: Occupancy | None = None
    source: Literal["world", "file", "none"] = "none"
    counters: dict[str, int] = {}
    surfaces: list[SupportSurface] = []
    if s.start == "prior":
        if not s.prior_file:
            raise ValueError("semantic_map.start = prior needs semantic_map.prior_file")
        mf = read_map_file(resolve(s.prior_file))
        check_site(f"the prior map file {s.prior_file}", mf.site, site)
        tracks = tracks_from_file(mf, "prior")
        counters = dict(mf.counters)
        surfaces = list(mf.supports)
        if mf.occupancy is not None:
            occ, source = occupancy_from_grid(mf.occupancy, **occ_kw), "file"
    if occ is None and (s.start == "seed-from-world" or s.floor_plan == "world"):
        w = world()
        if w is None and s.start == "seed-from-world":
            raise RuntimeError("seed-from-world: no simulator answers dume/world/description")
        if w is not None:
            if s.start == "seed-from-world":
                tracks = seed_from_world(w, s.seed_noise_m, s.seed_noise_seed)
            if s.floor_plan == "world":
                occ, source = occupancy_from_world(w, **occ_kw), "world"
                # the floor plan's tables and benches too: what may stand on them is
                # judged against their tops (`evidence`), as on an explored map's
                surfaces = surfaces or list(w.surfaces)
        else:
            log.warning("no world description: the static occupancy layer is unknown")
    if occ is None:
        occ = Occupancy.unknown(s.grid_half_extent_m, s.grid_resolution_m, **occ_kw)
    smap = SemanticMap(s, occ, counters)
    smap.static_source = source
    smap.surfaces = smap.surfaces_before = surfaces
    for tr in tracks:
        smap.add(tr)
    smap.forget_people_in_static()
    smap.site = site
    save_all(smap, store, {"start": s.start, "static_source": source})
    return smap, f"new map {store.path.name} of {site!r} from {s.start}: {len(tracks)} entities"


def save_all(smap: SemanticMap, store: MapStore, meta: dict[str, str] | None = None) -> None:
    """Write the whole map in one transaction (a new map, an import)."""
    smap.take_changes()
    occ = smap.occupancy
    store.commit(
        entities=[(t.to_message(), t.appearance) for t in smap.tracks()],
        counters=dict(smap.ids.counters),
        grids={"static": Grid(occ.static, occ.resolution_m, occ.origin_xy), **learned_grids(occ)},
        meta={
            "stamp_ns": str(smap.stamp_ns),
            "site": smap.site,
            "supports": surfaces_json(smap.surfaces),
            **(meta or {}),
        },
        replace=True,
    )


def _static_source(text: str) -> Literal["world", "file", "slam", "none"]:
    return text if text in ("world", "file", "slam") else "none"  # type: ignore[return-value]


def _resume(
    s: SemanticMapSettings, store: MapStore, occ_kw: dict[str, object], site: str
) -> tuple[SemanticMap, str]:
    snap = store.load()
    check_site(f"the database {store.path}", snap.meta.get("site", ""), site)
    g = snap.grids.get("static")
    if g is None:
        occ = Occupancy.unknown(s.grid_half_extent_m, s.grid_resolution_m, **occ_kw)
    else:
        hits = snap.grids.get("learned")
        top_z, top_n = snap.grids.get("top_z"), snap.grids.get("top_n")
        occ = Occupancy(
            g.cells.astype(np.uint8),
            g.resolution_m,
            g.origin_xy,
            hits=None if hits is None else hits.cells.astype(np.uint16),
            tops=None
            if top_z is None or top_n is None
            else (top_z.cells.astype(np.float32), top_n.cells.astype(np.uint16)),
            **occ_kw,  # type: ignore[arg-type]
        )
        low = snap.grids.get("low_z")
        if low is not None and low.cells.shape == occ.low_z.shape:
            occ.low_z = low.cells.astype(np.float32)  # a database of before: none, never cleared
    smap = SemanticMap(s, occ, snap.counters)
    for entity, app in snap.entities:
        smap.add(Track.from_message(entity, app))
    smap.take_changes()
    smap.stamp_ns = int(snap.meta.get("stamp_ns", "0"))
    smap.static_source = _static_source(snap.meta.get("static_source", "none"))
    smap.surfaces = smap.surfaces_before = _SURFACES.decode(snap.meta.get("supports", "[]"))
    smap.forget_people_in_static()  # a sensed layer's: `furniture`, `beside_static` too
    smap.site = site or snap.meta.get("site", "")
    if site and not snap.meta.get("site"):
        store.commit(meta={"site": site})  # from before sites were kept: it is this one's now
    n = len(snap.entities)
    return (
        smap,
        f"resumed {store.path.name} of {smap.site!r}: {n} entities, started as "
        f"{snap.meta.get('start', '?')}",
    )
