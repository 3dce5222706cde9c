"""The semantic map's payloads: artifacts and people with ids, the occupancy grid, the
floor plan's supports and the map file (JSON export/import).

Positions are in the `world` frame. `source` says where an entity's id came from:
`prior` (a map file loaded at start), `seed-from-world` (the simulator's truth ids and
noisy truth positions: sim truth, for experiments only), `perception` (a detection fused
by this map), `import` (a map file imported while running).
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from common.messages.arrays import Array
from common.messages.base import ClassName, EntityId, Finite, Message, NonNegative, StampNs, Vec3
from common.messages.world import SupportSurface

Source = Literal["prior", "seed-from-world", "perception", "import"]
EntityKind = Literal["artifact", "person"]


class SeenPlace(Message, frozen=True):
    """One of a person's usual places: where the map saw them, one `PLACE_CELL_M` cell of
    the floor (`services.semantic_map.whereabouts`).

    xy: the sightings' mean place there, m, world. sightings: how many (at most one a
    second: about the seconds they were seen there). last_seen_ns: the latest one's sim
    time, ns.
    """

    xy: tuple[Finite, Finite]
    sightings: Annotated[int, msgspec.Meta(ge=1)]
    last_seen_ns: StampNs


Histogram = Annotated[tuple[NonNegative, ...], msgspec.Meta(max_length=64)]


class PersonColours(Message, frozen=True):
    """A person's clothes as the map saw them, by range band (`common.appearance.Banded`):
    colour histograms (empty: no view in that band yet) and how many views each averages.
    far: whole views from 3 m on (shirt and trousers); near: views within 2 m (the legs).
    """

    far: Histogram = ()
    far_views: Annotated[int, msgspec.Meta(ge=0)] = 0
    near: Histogram = ()
    near_views: Annotated[int, msgspec.Meta(ge=0)] = 0


class MapEntity(Message, frozen=True):
    """`dume/map/artifacts/<id>` or `dume/map/people/<id>`: one mapped thing.

    position_in_world: (3,) m, the running estimate (an artifact's axis point at its
        visible centroid's height, a person's feet on the floor). uncertainty_m: 1-σ of the
        horizontal position, m.
    last_seen_ns: sim time of the last detection fused, ns (0: never since start).
    first_seen_ns: sim time of the first detection fused, ns (0: not made from this run's
        detections: seeded, imported, or from before the map's clock started).
    missing_since_ns: looked for at its place and not seen since then (None: not missing).
    velocity_in_world: (2,) m/s, a person's estimated floor velocity (0 for artifacts).
    observations: detections fused into it so far.
    nearest_view_m: an artifact's nearest view fused, its range from the camera's base, m
        (None: not known, as for one seeded or imported); the mapping patrol looks again
        at one seen only from afar.
    places: a person's usual places, most seen first (empty for artifacts, and for a
        person seeded from truth and not seen since): where to look for someone who is
        not where they were last seen.
    colours: a person's colours by range band (`PersonColours`; None for artifacts):
        the mission checks whom it hands over to against them.
    """

    id: EntityId
    class_name: ClassName
    kind: EntityKind
    position_in_world: Vec3
    uncertainty_m: NonNegative
    last_seen_ns: StampNs
    source: Source
    missing_since_ns: StampNs | None = None
    yaw: Finite = 0.0
    velocity_in_world: tuple[Finite, Finite] = (0.0, 0.0)
    observations: int = 0
    nearest_view_m: NonNegative | None = None
    places: Annotated[tuple[SeenPlace, ...], msgspec.Meta(max_length=64)] = ()
    colours: PersonColours | None = None
    first_seen_ns: StampNs = 0


class MapListing(Message, frozen=True):
    """Every entity of one kind (reply to `dume/map/artifacts` or `dume/map/people`).

    A query may filter by parameters: `?class=bottle`, `?missing=true`.
    """

    stamp_ns: StampNs
    entities: list[MapEntity]


class OccupancyGrid(Message, frozen=True):
    """`dume/map/occupancy`: the persistent grid.

    cells: (ny, nx) uint8, 0 free, 100 occupied, 255 unknown; cell [iy, ix] has its centre
    at origin + ((ix + 0.5) res, (iy + 0.5) res) in the world frame.
    resolution_m: cell size, m. origin_xy: world position of cell (0, 0)'s corner, m.
    static_source: where the static layer came from (`world`: the simulator's floor plan,
    `file`: a map file, `slam`: the robot's own lidar map, `none`). learned_cells: cells
    occupied by obstacles seen in depth.
    """

    stamp_ns: StampNs
    resolution_m: NonNegative
    origin_xy: tuple[Finite, Finite]
    cells: Array
    static_source: Literal["world", "file", "slam", "none"] = "none"
    learned_cells: int = 0


class MapFile(Message, frozen=True):
    """A whole map as a file (`dume map --export FILE`, `--import FILE`; JSON on disk).

    version: the format's version (1). counters: per class, the last number given
    (`{"bottle": 3}`), so ids stay unique after an import. occupancy: the merged grid
    (static + learned), the static layer of a map started from this file. site: the
    place it is a map of (`Config.map_site`: `hall seed 3`; empty in files from before
    sites were kept); a map service of another site refuses it. supports: the surfaces
    artifacts stand on, as the map saw them (`dume/map/supports` of a map with no floor
    plan), kept for the next run's semantic pass. appearances: people's colour
    histograms by id (`common/appearance.py`), so the next run knows
    somebody who walked off by their clothes (absent in older files).
    """

    version: Literal[1] = 1
    stamp_ns: StampNs = 0
    site: str = ""
    entities: list[MapEntity] = msgspec.field(default_factory=list)
    counters: dict[str, int] = msgspec.field(default_factory=dict)
    occupancy: OccupancyGrid | None = None
    supports: list[SupportSurface] = msgspec.field(default_factory=list)
    appearances: dict[str, list[float]] = msgspec.field(default_factory=dict)


class MapSummary(Message, frozen=True):
    """Reply to `dume/map/import`: what the map holds now."""

    stamp_ns: StampNs
    artifacts: int
    people: int
    missing: int


class SupportListing(Message, frozen=True):
    """`dume/map/supports`: the tables, benches and loaded pallets artifacts stand on
    (what the mapping patrol must see from near): the floor plan's with
    `semantic_map.floor_plan = "world"`, else the surfaces the map saw at working height
    (`services/semantic_map/supports.py`).
    """

    stamp_ns: StampNs
    surfaces: list[SupportSurface] = msgspec.field(default_factory=list)
