"""What the map writes to its database at the end of a tick, and when it closes.

`TickCommitter.commit(smap, b)` (b: the tick, sim ns) moves the map's stamp up to b and
writes, in one SQLite transaction (`MapStore.commit`), the entities changed and deleted
since the last tick, the id counters if they changed, the learned occupancy layer when
it changed and `GRID_EVERY_NS` of sim time have passed since it was last written, and
the tick as `stamp_ns`; a tick that changed nothing writes nothing. The node acks b
only after it returns. `close(smap)` writes the learned layer a last time and closes the
database. Both are called with the map's lock held (the tick thread, the node's close).
"""

from __future__ import annotations

import msgspec

from common.messages.base import NS_PER_S
from common.messages.world import SupportSurface
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.store import Grid, MapStore

_SURFACES = msgspec.json.Encoder()


def learned_grids(occ: Occupancy) -> dict[str, Grid]:
    """The layers the map learns as it looks: obstacle hits (and each cell's lowest hit,
    which says whether it may be cleared) and the tops."""
    g = (occ.resolution_m, occ.origin_xy)
    return {
        "learned": Grid(occ.hits, *g),
        "low_z": Grid(occ.low_z, *g),
        "top_z": Grid(occ.top_z, *g),
        "top_n": Grid(occ.top_n, *g),
    }


def surfaces_json(surfaces: list[SupportSurface]) -> str:
    return _SURFACES.encode(surfaces).decode()


#: Sim ns between writes of a changed learned occupancy layer.
GRID_EVERY_NS = 2 * NS_PER_S


class TickCommitter:
    def __init__(self, store: MapStore) -> None:
        self.store = store
        #: The tick at which the learned layer was last written (sim ns).
        self.last_grid_save = 0

    def commit(self, smap: SemanticMap, b: int) -> None:
        smap.stamp_ns = max(smap.stamp_ns, b)
        changed, counters = smap.take_changes()
        deleted = smap.take_deletions()
        grids = None
        occ = smap.occupancy
        if smap.grid_dirty and b - self.last_grid_save >= GRID_EVERY_NS:
            grids = learned_grids(occ)
            smap.grid_dirty = False
            self.last_grid_save = b
        meta = {"stamp_ns": str(b)}
        if smap.static_dirty:  # the SLAM grid: written with its source at once
            grids = dict(grids or {})
            grids["static"] = Grid(occ.static, occ.resolution_m, occ.origin_xy)
            meta["static_source"] = smap.static_source
            smap.static_dirty = False
        if smap.surfaces_dirty:
            meta["supports"] = surfaces_json(smap.surfaces)
            smap.surfaces_dirty = False
        if not changed and not deleted and counters is None and grids is None and len(meta) == 1:
            return
        self.store.commit(
            entities=[(t.to_message(), t.appearance) for t in changed],
            counters=counters,
            grids=grids,
            meta=meta,
            deleted=deleted,
        )

    def close(self, smap: SemanticMap) -> None:
        occ = smap.occupancy
        self.store.commit(grids=learned_grids(occ), meta={"supports": surfaces_json(smap.surfaces)})
        self.store.close()
