"""The map's SQLite database: entities, id counters and the occupancy layers.

One file per map (`<dir>/<name>.sqlite`) in WAL mode with `synchronous=FULL`. Every
change of one tick (entities written or deleted, counters, grids) goes in one
transaction (`commit`), and the node acknowledges the tick
only after it returns: a SIGKILL at any moment leaves the database as of the last
committed transaction — the last acknowledged write is kept, nothing half-written is seen.
Appearance histograms travel as float32 blobs; grids as zlib-compressed bytes.
"""

from __future__ import annotations

import re
import sqlite3
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np
from numpy.typing import NDArray

from common.config import SemanticMapSettings, resolve
from common.geometry import FloatArray
from common.messages import decoder
from common.messages.semantic_map import MapEntity

SCHEMA = """
CREATE TABLE IF NOT EXISTS entities (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    entity BLOB NOT NULL,
    appearance BLOB
);
CREATE TABLE IF NOT EXISTS counters (class_name TEXT PRIMARY KEY, last INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS grids (
    name TEXT PRIMARY KEY,
    dtype TEXT NOT NULL,
    ny INTEGER NOT NULL,
    nx INTEGER NOT NULL,
    resolution REAL NOT NULL,
    origin_x REAL NOT NULL,
    origin_y REAL NOT NULL,
    data BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""

_ENC = msgspec.msgpack.Encoder()
_DEC = decoder(MapEntity)


def site_slug(site: str) -> str:
    """A site as a file name: `hall seed 3` → `hall-seed-3`."""
    return re.sub(r"[^a-z0-9]+", "-", site.lower()).strip("-")


def database_path(settings: SemanticMapSettings, name: str | None = None, site: str = "") -> Path:
    """The file of map `name` (the settings' own by default, else the site's, else
    `default`): `<dir>/<name>.sqlite`."""
    stem = name or settings.name or site_slug(site)
    return resolve(settings.dir) / f"{stem or 'default'}.sqlite"


def remove_database(path: Path) -> None:
    """Delete a map's database with its WAL and shared-memory files (none may have it
    open: a stopped stack, or a map starting over)."""
    for suffix in ("", "-wal", "-shm"):
        path.with_name(path.name + suffix).unlink(missing_ok=True)


@dataclass(frozen=True)
class Grid:
    """A stored grid layer."""

    cells: NDArray[np.generic]
    resolution_m: float
    origin_xy: tuple[float, float]


@dataclass
class Snapshot:
    """Everything a map database holds."""

    entities: list[tuple[MapEntity, FloatArray | None]]
    counters: dict[str, int]
    grids: dict[str, Grid]
    meta: dict[str, str]


class MapStore:
    """A map database; `commit` writes one tick's changes in one transaction."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.conn = sqlite3.connect(str(path), isolation_level=None, check_same_thread=False)
        self.conn.execute("PRAGMA journal_mode=WAL")
        self.conn.execute("PRAGMA synchronous=FULL")
        self.conn.executescript(SCHEMA)

    def close(self) -> None:
        self.conn.close()

    def integrity(self) -> str:
        """SQLite's `integrity_check`: `ok` for a sound file."""
        return str(self.conn.execute("PRAGMA integrity_check").fetchone()[0])

    def is_empty(self) -> bool:
        return self.conn.execute("SELECT COUNT(*) FROM meta").fetchone()[0] == 0

    def load(self) -> Snapshot:
        entities = []
        for blob, app in self.conn.execute("SELECT entity, appearance FROM entities ORDER BY id"):
            appearance = None if app is None else np.frombuffer(app, np.float32).astype(float)
            entities.append((_DEC.decode(blob), appearance))
        counters = dict(self.conn.execute("SELECT class_name, last FROM counters"))
        grids = {}
        for name, dtype, ny, nx, res, ox, oy, data in self.conn.execute("SELECT * FROM grids"):
            cells = np.frombuffer(zlib.decompress(data), dtype=dtype).reshape(ny, nx).copy()
            grids[name] = Grid(cells, res, (ox, oy))
        meta = dict(self.conn.execute("SELECT key, value FROM meta"))
        return Snapshot(entities, counters, grids, meta)

    def commit(
        self,
        entities: Iterable[tuple[MapEntity, FloatArray | None]] = (),
        counters: dict[str, int] | None = None,
        grids: dict[str, Grid] | None = None,
        meta: dict[str, str] | None = None,
        replace: bool = False,
        deleted: Iterable[str] = (),
    ) -> None:
        """Write these changes atomically; `replace` clears the entities first (an import);
        the entities with the ids in `deleted` are removed (after the writes)."""
        cur = self.conn.cursor()
        cur.execute("BEGIN IMMEDIATE")
        try:
            if replace:
                cur.execute("DELETE FROM entities")
                cur.execute("DELETE FROM counters")
            cur.executemany(
                "INSERT OR REPLACE INTO entities (id, kind, entity, appearance) VALUES (?,?,?,?)",
                [
                    (
                        e.id,
                        e.kind,
                        _ENC.encode(e),
                        None if app is None else np.asarray(app, np.float32).tobytes(),
                    )
                    for e, app in entities
                ],
            )
            cur.executemany("DELETE FROM entities WHERE id = ?", [(i,) for i in deleted])
            if counters:
                cur.executemany(
                    "INSERT OR REPLACE INTO counters (class_name, last) VALUES (?,?)",
                    sorted(counters.items()),
                )
            for name, g in (grids or {}).items():
                cells = np.ascontiguousarray(g.cells)
                cur.execute(
                    "INSERT OR REPLACE INTO grids VALUES (?,?,?,?,?,?,?,?)",
                    (
                        name,
                        cells.dtype.name,
                        cells.shape[0],
                        cells.shape[1],
                        g.resolution_m,
                        g.origin_xy[0],
                        g.origin_xy[1],
                        zlib.compress(cells.tobytes(), 3),
                    ),
                )
            if meta:
                cur.executemany(
                    "INSERT OR REPLACE INTO meta (key, value) VALUES (?,?)", sorted(meta.items())
                )
            cur.execute("COMMIT")
        except BaseException:
            cur.execute("ROLLBACK")
            raise
