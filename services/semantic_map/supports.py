"""`dume/map/supports`: the floor plan's tables and benches, served to the mapping patrol.

With `floor_plan = "world"` the floor plan is the sim's world description (the building's
plan, as the static occupancy layer is): its support surfaces are fetched once, through
`world(wait_s)`, on the first query that needs them, and kept (`surfaces`). Without a floor plan the
listing is empty. A world description that does not come is `unavailable` (asked again
by the next query). The node calls `listing` on the queryable's thread, without the
map's lock: the fetch may wait up to `WORLD_WAIT_S` wall seconds.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from common.bus import RequestError
from common.messages.world import SupportSurface, WorldDescription

#: Wall seconds a query waits for the world description.
WORLD_WAIT_S = 5.0
log = logging.getLogger("dume.semantic_map")


class FloorPlanSupports:
    """The floor plan's support surfaces, fetched once (see the module docstring)."""

    def __init__(self, floor_plan: str, world: Callable[[float], WorldDescription | None]) -> None:
        self.floor_plan, self.world = floor_plan, world
        self._surfaces: list[SupportSurface] | None = None
        self._lock = threading.Lock()

    def surfaces(self) -> list[SupportSurface]:
        if self.floor_plan != "world":
            return []
        with self._lock:
            if self._surfaces is None:
                w = self.world(WORLD_WAIT_S)
                if w is None:
                    raise RequestError(
                        "unavailable", "no world description: the floor plan's supports are unknown"
                    )
                self._surfaces = list(w.surfaces)
                log.info("floor plan: %d tables and benches", len(self._surfaces))
            return self._surfaces
