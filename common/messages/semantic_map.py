"""The semantic map's payloads: artifacts and people with ids, and the occupancy grid."""

from __future__ import annotations

from typing import Literal

from common.messages.arrays import Array
from common.messages.base import ClassName, EntityId, Finite, Message, NonNegative, StampNs, Vec3

Source = Literal["prior", "seed-from-world", "perception", "import"]


class MapEntity(Message, frozen=True):
    """`dume/map/artifacts/<id>` or `dume/map/people/<id>`: one mapped thing.

    position_in_world: (3,) m, the running estimate (an artifact's centre, a person's
        feet). uncertainty_m: 1-σ of the horizontal position, m.
    last_seen_ns: sim time of the last detection fused, ns (0: never since start).
    missing_since_ns: looked for at its place and not seen since then (None: not missing).
    """

    id: EntityId
    class_name: ClassName
    kind: Literal["artifact", "person"]
    position_in_world: Vec3
    uncertainty_m: NonNegative
    last_seen_ns: StampNs
    source: Source
    missing_since_ns: StampNs | None = None
    yaw: Finite = 0.0


class MapListing(Message, frozen=True):
    """Every entity of one kind (reply to `dume/map/artifacts` or `dume/map/people`)."""

    stamp_ns: StampNs
    entities: list[MapEntity]


class OccupancyGrid(Message, frozen=True):
    """`dume/map/occupancy`: the persistent grid.

    cells: (ny, nx) uint8, 0 free, 100 occupied, 255 unknown; cell [iy, ix] has its centre
    at origin + ((ix + 0.5) res, (iy + 0.5) res) in the world frame.
    resolution_m: cell size, m. origin_xy: world position of cell (0, 0)'s corner, m.
    """

    stamp_ns: StampNs
    resolution_m: NonNegative
    origin_xy: tuple[Finite, Finite]
    cells: Array
