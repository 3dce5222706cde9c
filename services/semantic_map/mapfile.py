"""Where a map starts from, and the map file: a prior (JSON export of an earlier run), the
simulator's truth with noise (`seed-from-world`), and export/import.

A map file is a `MapFile` as JSON (arrays base64): the confirmed entities, the id
counters and the merged occupancy grid, which becomes the static layer of a map started
from it. Seeding from the world reuses the sim's ids and truth positions plus Gaussian
noise (named `seed-from-world` in every entity's `source`: it is sim truth).
"""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np

from common.appearance import SIZE
from common.geometry import FloatArray
from common.messages import as_numpy, decoder
from common.messages.semantic_map import MapFile, OccupancyGrid, Source
from common.messages.world import Cuboid, WorldDescription
from common.runfiles import write_whole
from services.semantic_map.entities import Track
from services.semantic_map.occupancy import FREE, OCCUPIED, UNKNOWN, Occupancy


class MapFileError(ValueError):
    """A map file that cannot be read: which file and what is wrong."""


def read_map_file(path: Path) -> MapFile:
    try:
        return decoder(MapFile, "json").decode(path.read_bytes())
    except FileNotFoundError:
        raise MapFileError(f"map file {path} does not exist") from None
    except msgspec.DecodeError as exc:
        raise MapFileError(f"map file {path} is not a dume map (MapFile JSON): {exc}") from None


def write_map_file(path: Path, mf: MapFile) -> None:
    """Write atomically (a temporary file renamed over the target)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_whole(path, msgspec.json.format(msgspec.json.encode(mf), indent=1))


def tracks_from_file(mf: MapFile, source: Source) -> list[Track]:
    """The file's entities as confirmed tracks, renamed to `source` (`prior` or `import`),
    people with their colours (`MapFile.appearances`; `ValueError` for a histogram that
    is not one). Their stamps are another run's clock: each is not seen since this run
    started (`last_seen_ns` and `first_seen_ns` 0), and one missing in the file is
    missing since before it (0). A file's stamp of 500 s read in a run at 200 s was "seen
    300 s from now": a person of the file counted as seen lately, and artifacts as seen
    after a search began."""
    tracks = [
        Track.from_message(msgspec.structs.replace(
            e, source=source, last_seen_ns=0, first_seen_ns=0,
            missing_since_ns=None if e.missing_since_ns is None else 0,
        ))
        for e in mf.entities
    ]  # fmt: skip
    for tr in tracks:
        if tr.id in mf.appearances and tr.kind == "person":
            tr.appearance = appearance_from_file(tr.id, mf.appearances[tr.id])
    return tracks


def appearance_from_file(entity_id: str, values: list[float]) -> FloatArray:
    """A person's colour histogram as a file keeps it; `ValueError` unless it is one
    (`appearance.SIZE` finite non-negative bins summing to 1)."""
    h = np.asarray(values, dtype=float)
    if h.shape != (SIZE,) or not np.isfinite(h).all() or (h < 0).any() or abs(h.sum() - 1) > 0.01:
        raise ValueError(f"{entity_id}'s colours are not a {SIZE}-bin histogram")
    return h / h.sum()


def occupancy_from_grid(grid: OccupancyGrid, **kw: object) -> Occupancy:
    """The grid as the map's occupancy; `ValueError` saying why when it cannot be one
    (cells not a 2-D uint8 grid of 0, 100 and 255; a cell size not above 0)."""
    cells = as_numpy(grid.cells)  # ArrayError (a ValueError): dtype, shape and bytes disagree
    if cells.dtype != np.uint8 or cells.ndim != 2 or 0 in cells.shape:
        raise ValueError(f"cells must be a 2-D uint8 grid, not {cells.dtype} {cells.shape}")
    if not grid.resolution_m > 0.0:
        raise ValueError(f"the cell size must be above 0 m, not {grid.resolution_m}")
    if not np.isin(cells, (FREE, OCCUPIED, UNKNOWN)).all():
        raise ValueError("cells must be 0 (free), 100 (occupied) or 255 (unknown)")
    return Occupancy(cells, grid.resolution_m, grid.origin_xy, **kw)  # type: ignore[arg-type]


def occupancy_from_world(world: WorldDescription, **kw: object) -> Occupancy:
    """The floor plan: the simulator's static grid (walls, furniture; no people)."""
    g = world.occupancy
    cells = np.asarray(as_numpy(g.cells), np.uint8)
    return Occupancy(cells, g.resolution, g.origin, **kw)  # type: ignore[arg-type]


def seed_from_world(world: WorldDescription, noise_m: float, seed: int) -> list[Track]:
    """Every artifact and person of the world, with its truth id, at its truth position plus
    N(0, noise_m²) horizontally; an artifact's height is its body's mid-height."""
    rng = np.random.default_rng(seed)
    sigma = max(noise_m, 0.01)
    out = []
    for a in world.artifacts:
        half = a.shape.half_size[2] if isinstance(a.shape, Cuboid) else a.shape.height / 2
        out.append(
            Track(
                class_name=a.object_class,
                kind="artifact",
                xy=np.array(a.position[:2]) + rng.normal(0.0, noise_m, 2),
                cov=np.eye(2) * sigma**2,
                z=a.position[2] + half,
                source="seed-from-world",
                id=a.id,
                yaw=a.yaw,
            )
        )
    for p in world.people:
        out.append(
            Track(
                class_name="person",
                kind="person",
                xy=np.array(p.position) + rng.normal(0.0, noise_m, 2),
                cov=np.eye(2) * sigma**2,
                z=0.0,
                source="seed-from-world",
                id=p.id,
                yaw=p.yaw,
            )
        )
    return out
