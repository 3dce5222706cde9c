"""The map as of a tick: what the queryables answer a lockstep consumer from.

The map changes only in its ticks (every `period_s` of sim time); a consumer that asks at
its own tick t may find the map one tick further than in another run of the same seed,
depending on which process the machine ran first. So every tick leaves a `MapView` (the
entities and the grid as they stand after it) and a query with `?at=<t>` is answered
from the view of the map's last tick whose output takes effect by t (its tick b with
b + latency ≤ t: in lockstep the sim cannot have published t before the map acked b,
so that view exists). A query without `at` gets the newest view: the map now.

Building a view costs the entities' messages (tens of them); the grid message is built
again only when the grid's cells changed (`Occupancy.version`), else shared.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

from common.messages.semantic_map import EntityKind, MapEntity, OccupancyGrid
from common.messages.world import SupportSurface
from services.semantic_map.mapper import SemanticMap, resolve_alias

#: Views kept: a consumer at most a few ticks behind the map still finds its own.
KEPT = 16


@dataclass(frozen=True)
class MapView:
    """The map after the tick at `tick_ns` (−1: before the first); reads like `SemanticMap`
    for the query functions (`entities`, `entity`, `stamp_ns`)."""

    tick_ns: int
    stamp_ns: int
    artifacts: tuple[MapEntity, ...]
    people: tuple[MapEntity, ...]
    grid_version: tuple[int, int]
    occupancy: OccupancyGrid
    surfaces: tuple[SupportSurface, ...] = ()
    #: A person's id merged away → the id kept (`SemanticMap.aliases`).
    aliases: Mapping[str, str] = field(default_factory=dict)

    def entities(self, kind: EntityKind) -> list[MapEntity]:
        return list(self.people if kind == "person" else self.artifacts)

    def entity(self, kind: EntityKind, entity_id: str) -> MapEntity | None:
        if kind == "person":
            entity_id = resolve_alias(dict(self.aliases), entity_id)
        return next((e for e in self.entities(kind) if e.id == entity_id), None)

    def grid(self) -> OccupancyGrid:
        return self.occupancy


def view_of(smap: SemanticMap, tick_ns: int, previous: MapView | None) -> MapView:
    """The map's view now, after the tick at `tick_ns` (the grid shared with `previous`
    when its cells did not change)."""
    occ = smap.occupancy
    version = (id(occ), occ.version)
    same_grid = previous is not None and previous.grid_version == version
    return MapView(
        tick_ns=tick_ns,
        stamp_ns=smap.stamp_ns,
        artifacts=tuple(smap.entities("artifact")),
        people=tuple(smap.entities("person")),
        grid_version=version,
        occupancy=previous.occupancy if same_grid and previous else smap.grid(),
        surfaces=tuple(smap.surfaces),
        aliases=dict(smap.aliases),
    )


class ViewHistory:
    """The last `KEPT` views, and which one answers a query as of a sim time."""

    def __init__(self, period_ns: int, latency_ns: int, wait: bool = True) -> None:
        self.period_ns, self.latency_ns = period_ns, latency_ns
        #: Wait for the map to reach an asked time (lockstep); in real time, answer now.
        self.wait = wait
        self._views: deque[MapView] = deque(maxlen=KEPT)
        self._cond = threading.Condition()

    def add(self, view: MapView) -> None:
        with self._cond:
            self._views.append(view)
            self._cond.notify_all()

    def reset(self, view: MapView) -> None:
        """The map changed outside its ticks (an import): only `view` is left."""
        with self._cond:
            self._views.clear()
            self._views.append(view)
            self._cond.notify_all()

    def record(self, smap: SemanticMap, tick_ns: int) -> None:
        """Keep the map's view after its tick at `tick_ns` (−1: before the first)."""
        self.add(view_of(smap, tick_ns, self.newest))

    def restart(self, smap: SemanticMap) -> None:
        """The map changed outside its ticks (an import): its view now, as of the newest
        tick, is the only one left."""
        newest = self.newest
        self.reset(view_of(smap, newest.tick_ns if newest else -1, None))

    @property
    def newest(self) -> MapView | None:
        with self._cond:
            return self._views[-1] if self._views else None

    def due_tick(self, at_ns: int) -> int:
        """The map's last tick whose output takes effect by `at_ns` (−1: none)."""
        due = at_ns - self.latency_ns
        return (due // self.period_ns) * self.period_ns if due >= 0 else -1

    def at(self, at_ns: int | None, timeout_s: float = 5.0) -> MapView | None:
        """The view a consumer at `at_ns` reads (waiting, bounded, for the map to get
        there); the newest for None, or when the map does not get there in time."""
        with self._cond:
            if at_ns is None or not self._views:
                return self._views[-1] if self._views else None
            want = self.due_tick(at_ns)
            if self.wait:
                self._cond.wait_for(lambda: self._views[-1].tick_ns >= want, timeout_s)
            for view in reversed(self._views):
                if view.tick_ns <= want:
                    return view
            return self._views[0]
