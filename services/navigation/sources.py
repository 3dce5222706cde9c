"""Where navigation's map comes from: the semantic map, or the sim's truth (tests only).

`MapSource` (`navigation.map_source = "map"`) queries `dume/map/occupancy` for the grid,
`dume/map/artifacts/<id>` and `dume/map/people/<id>` for one entity and `dume/map/people`
for everyone. `WorldSource` (`"world"`) reads `dume/world/description` once — the
simulator's **truth** (occupancy, artifacts, people at t = 0, who stand still unless
`sim.walking_people`), named as truth in every log line; for tests and development only.
Both raise `SourceError` with a sentence when something is missing.
"""

from __future__ import annotations

import logging
import threading
from typing import Protocol

from common import keys as K
from common.bus import Bus, BusError
from common.messages.semantic_map import MapEntity, MapListing, OccupancyGrid
from common.messages.world import WorldDescription
from services.navigation.costmap import Person
from services.navigation.grid import Grid

log = logging.getLogger(__name__)


class SourceError(RuntimeError):
    """The map cannot answer: which key, and why."""


class Source(Protocol):
    """`at_ns`: the map as of that sim time (a lockstep participant's tick); None: now."""

    name: str

    def grid(self, at_ns: int | None = None) -> Grid: ...
    def artifact_xy(self, artifact_id: str, at_ns: int | None = None) -> tuple[float, float]: ...
    def person(self, person_id: str, at_ns: int | None = None) -> Person: ...
    def people(self, at_ns: int | None = None) -> list[Person]: ...


class WorldSource:
    """The sim's truth description (tests and development only)."""

    name = "world (sim truth)"

    def __init__(self, bus: Bus, timeout_s: float = 30.0) -> None:
        try:
            self.world = bus.query(K.WORLD_DESCRIPTION, None, WorldDescription, timeout_s)
        except BusError as exc:
            raise SourceError(f"{K.WORLD_DESCRIPTION} (truth): {exc}") from None
        log.warning(
            "map source: the sim's TRUTH (%s, %s seed %d): tests and development only",
            K.WORLD_DESCRIPTION,
            self.world.name,
            self.world.seed,
        )

    def grid(self, at_ns: int | None = None) -> Grid:
        return Grid.from_world(self.world.occupancy)

    def artifact_xy(self, artifact_id: str, at_ns: int | None = None) -> tuple[float, float]:
        for a in self.world.artifacts:
            if a.id == artifact_id:
                return a.position[0], a.position[1]
        known = sorted(a.id for a in self.world.artifacts)
        raise SourceError(f"no artifact {artifact_id!r} in the truth world; it has {known}")

    def person(self, person_id: str, at_ns: int | None = None) -> Person:
        for p in self.people():
            if p.id == person_id:
                return p
        known = sorted(p.id for p in self.world.people)
        raise SourceError(f"no person {person_id!r} in the truth world; it has {known}")

    def people(self, at_ns: int | None = None) -> list[Person]:
        return [Person(p.id, p.position[0], p.position[1], p.yaw) for p in self.world.people]


def wait_for_world(bus: Bus, stop: threading.Event, log: logging.Logger) -> WorldSource:
    """The truth description, asked for until the sim answers (`SourceError` once `stop`
    is set)."""
    while True:
        try:
            return WorldSource(bus, timeout_s=5.0)
        except SourceError as exc:
            log.info("waiting for the sim: %s", exc)
            if stop.wait(0.5):
                raise


class MapSource:
    """The semantic map's queryables."""

    name = "semantic map"

    def __init__(self, bus: Bus, timeout_s: float = 2.0) -> None:
        self.bus, self.timeout_s = bus, timeout_s

    def _query(self, key: str, reply: type, what: str, at_ns: int | None):  # type: ignore[no-untyped-def]
        try:
            return self.bus.query(K.as_of(key, at_ns), None, reply, self.timeout_s)
        except BusError as exc:
            raise SourceError(f"{what} ({key}): {exc}") from None

    def grid(self, at_ns: int | None = None) -> Grid:
        msg: OccupancyGrid = self._query(K.MAP_OCCUPANCY, OccupancyGrid, "occupancy", at_ns)
        return Grid.from_map(msg)

    def artifact_xy(self, artifact_id: str, at_ns: int | None = None) -> tuple[float, float]:
        e: MapEntity = self._query(K.map_artifact(artifact_id), MapEntity, artifact_id, at_ns)
        return e.position_in_world[0], e.position_in_world[1]

    def person(self, person_id: str, at_ns: int | None = None) -> Person:
        e: MapEntity = self._query(K.map_person(person_id), MapEntity, person_id, at_ns)
        return _person(e)

    def people(self, at_ns: int | None = None) -> list[Person]:
        listing: MapListing = self._query(K.MAP_PEOPLE, MapListing, "people", at_ns)
        return [_person(e) for e in listing.entities if e.missing_since_ns is None]


def _person(e: MapEntity) -> Person:
    # The map's yaw of a person is where they face when it was estimated; 0.0 is also the
    # default of an entity without one, so it is only trusted when non-zero.
    yaw = e.yaw if e.yaw != 0.0 else None
    vx, vy = e.velocity_in_world
    return Person(
        e.id, e.position_in_world[0], e.position_in_world[1], yaw, (vx, vy), e.last_seen_ns
    )
