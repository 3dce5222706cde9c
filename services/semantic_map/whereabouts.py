"""A person's usual places: where the map has seen them, counted on a grid of the floor.

A person not where the map last saw them is looked for where they are usually seen, as a
colleague would: at their bench, along the aisle they walk. Every detection fused into a
confirmed person (`PeopleTracker._fuse`) is a sighting; at most one a `EVERY_NS` per person
is counted (so a count is about the seconds they were seen there, whatever the camera's
rate), in the `CELL_M` cell it falls in, with the sightings' mean place and the latest
time. A walker on a loop leaves the loop's cells, a worker at a bench one cell with a
large count. At most `MAX_PLACES` cells are kept: a new cell past that replaces the least
seen (the oldest of those). Two tracks found to be one person (a split merged back, one
re-identified) pool their places. The places travel with the person's `MapEntity`
(`places`, most seen first), so they are stored with the map, exported and imported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from common.geometry import FloatArray
from common.messages.semantic_map import SeenPlace

CELL_M = 1.0
EVERY_NS = 1_000_000_000
MAX_PLACES = 64


@dataclass
class _Cell:
    sightings: int
    sum_x: float
    sum_y: float
    last_ns: int


@dataclass
class Whereabouts:
    """One person's places (module docstring); `last_ns`: the last sighting counted."""

    cells: dict[tuple[int, int], _Cell] = field(default_factory=dict)
    last_ns: int = -1
    #: `places()` as last ranked (the entity's message is made every frame it is seen;
    #: the cells change once a second at most), None when a change came since.
    _ranked: tuple[SeenPlace, ...] | None = field(default=None, repr=False, compare=False)

    def see(self, xy: FloatArray | tuple[float, float], stamp_ns: int) -> bool:
        """Count a sighting at xy (m, world) unless one was counted within `EVERY_NS`
        before it (a clock that went back counts afresh); whether it was."""
        if self.last_ns >= 0 and 0 <= stamp_ns - self.last_ns < EVERY_NS:
            return False
        x, y = float(xy[0]), float(xy[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            return False
        self.last_ns, self._ranked = stamp_ns, None
        key = (math.floor(x / CELL_M), math.floor(y / CELL_M))
        cell = self.cells.get(key)
        if cell is None:
            self._make_room()
            self.cells[key] = _Cell(1, x, y, stamp_ns)
            return True
        cell.sightings += 1
        cell.sum_x += x
        cell.sum_y += y
        cell.last_ns = max(cell.last_ns, stamp_ns)
        return True

    def _make_room(self) -> None:
        while len(self.cells) >= MAX_PLACES:
            least = min(self.cells, key=lambda k: (self.cells[k].sightings, self.cells[k].last_ns))
            del self.cells[least]

    def absorb(self, other: Whereabouts) -> None:
        """Pool another track's places into these (the two are one person)."""
        self._ranked = None
        for key, c in other.cells.items():
            mine = self.cells.get(key)
            if mine is None:
                self._make_room()
                self.cells[key] = _Cell(c.sightings, c.sum_x, c.sum_y, c.last_ns)
                continue
            mine.sightings += c.sightings
            mine.sum_x += c.sum_x
            mine.sum_y += c.sum_y
            mine.last_ns = max(mine.last_ns, c.last_ns)
        self.last_ns = max(self.last_ns, other.last_ns)

    def places(self) -> tuple[SeenPlace, ...]:
        """Most seen first (then the latest first)."""
        if self._ranked is None:
            ranked = sorted(self.cells.values(), key=lambda c: (-c.sightings, -c.last_ns))
            self._ranked = tuple(
                SeenPlace(
                    xy=(c.sum_x / c.sightings, c.sum_y / c.sightings),
                    sightings=c.sightings,
                    last_seen_ns=c.last_ns,
                )
                for c in ranked
            )
        return self._ranked

    @classmethod
    def of(cls, places: tuple[SeenPlace, ...]) -> Whereabouts:
        """The places a stored or imported person came with."""
        w = cls()
        for p in places:
            key = (math.floor(p.xy[0] / CELL_M), math.floor(p.xy[1] / CELL_M))
            n = p.sightings
            w.absorb(cls({key: _Cell(n, p.xy[0] * n, p.xy[1] * n, p.last_seen_ns)}))
        w.last_ns = -1
        return w
