"""The persistent occupancy layer: a static grid plus obstacles seen in depth that stay.

The static layer comes from a map file, the robot's own SLAM grid (adopted as it grows),
or the simulator's floor plan (`WorldDescription`'s
5 cm grid) — or is all unknown. The learned layer counts, per cell, the depth frames in
which points between `z_range` hit it (each frame counts a cell once); at `hits` frames
the cell is a learned obstacle. Floor points (below 5 cm) make unknown cells free. Points
on people and near the robot are left out by the caller (people move: they are the map's
people, not obstacles). Navigation keeps its own short-lived layer.

What stood on the floor and went is forgotten: a cell whose hits came down to
`LOW_HIT_M` (a thing standing there, not a table top or a shelf above the floor) and
which `CLEAR_FRAMES` frames in a row then saw as floor, with no point of `z_range` in
it, has its hits reset (a hit in the cell restarts the count). The detector misses
people, most of all near the robot where the head camera sees only legs: hall seed 4's
shift learned a cell from a worker's legs missed at 17 s and again at 294 s, and from
325 s the body guard, holding the robot off it, wedged the robot there among crossing
workers for the rest of the shift (two requests lost). Replayed over that shift's 7756
frames, the rule (with 5 frames) cleared 424 of the 551 cells people had left and that
one 18 s before the wedge; a table's cells hold no low hit (the camera sees the floor
under its top), so the tables an explored map learns stay.

The tops layer (`top_z`, `top_n`): per cell the highest point a frame saw there, kept as
the running top, and how many frames saw the top within `TOP_TOL_M` of it: what
`supports.surfaces_from_tops` reads the tables, benches and loaded pallets from (a
horizontal surface at working height is a patch of cells with one top many frames saw).
A frame counts a cell's highest point as its top only where it saw over it
(`integrate`'s `sees_over`, `looks.sees_over`: the ray to `OVER_M` above the point lies
in the picture and goes on past it): else what stands there may go on above the
picture, as a wall does. The head camera's picture ends 1.0-1.3 m up on a wall 2.5-4 m
away: the explored small world's walls were "surfaces" at those heights, which its
semantic pass walked to (10 viewpoints for 3 "surfaces" where the room has one table).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from common.geometry import FloatArray

FREE, OCCUPIED, UNKNOWN = 0, 100, 255
FLOOR_Z_M = 0.05
#: A frame's highest point in a cell within this of the cell's top confirms it, m.
TOP_TOL_M = 0.03
#: A top is seen over when the camera sees past this far above it, m (`integrate`).
OVER_M = 0.03

#: Which points (N, 3; world) a frame sees past (`looks.sees_over`).
SeesOver = Callable[[FloatArray], NDArray[np.bool_]]
#: Frames in a row that see a cell as floor, with no point of `z_range` in it, before
#: its hits are reset; and how low a cell's lowest hit must have come for that, m (what
#: stands on the floor: a person's legs, a part left there; not a top above it).
CLEAR_FRAMES = 5
LOW_HIT_M = 0.5
#: An obstacle blob of a lidar map at most this across may be a person standing, m.
PERSON_BLOB_M = 0.8
#: A sensed static layer's blobs at most this across are a table's or a bench's legs: the
#: depth learns the top above them (`Occupancy.sensed`), m.
LEG_BLOB_M = 0.3


def without_blobs(occupied: NDArray[np.bool_], max_cells: float) -> NDArray[np.bool_]:
    """`occupied` less its 8-connected blobs at most `max_cells` across both ways."""
    labels, _n = ndimage.label(occupied, structure=np.ones((3, 3), bool))
    out = occupied.copy()
    for k, box in enumerate(ndimage.find_objects(labels), start=1):
        if box is None:
            continue
        if box[0].stop - box[0].start <= max_cells and box[1].stop - box[1].start <= max_cells:
            out[box] &= labels[box] != k
    return out


class Occupancy:
    """Static + learned cells on one grid: cell [iy, ix] spans origin + (i, i+1) × res."""

    def __init__(
        self,
        static: NDArray[np.uint8],
        resolution_m: float,
        origin_xy: tuple[float, float],
        hits_needed: int = 3,
        z_range: tuple[float, float] = (0.15, 1.9),
        hits: NDArray[np.uint16] | None = None,
        tops: tuple[NDArray[np.float32], NDArray[np.uint16]] | None = None,
        sensed: tuple[int, float] = (3, 0.05),
    ) -> None:
        self.static = np.ascontiguousarray(static, dtype=np.uint8)
        #: The static layer's obstacle cells (changed only by `adopt_static`).
        self.static_occupied: NDArray[np.bool_] = self.static == OCCUPIED
        #: The static obstacles nobody stands on (a floor plan's all; of a SLAM grid, not
        #: the blobs a standing person leaves: `adopt_static`).
        self.furniture: NDArray[np.bool_] = self.static_occupied
        #: Of a sensed static layer, its obstacles (but small blobs: legs) grown by
        #: `sensed[1]` m: the depth learns no obstacle there (the lidar saw that face; the
        #: depth's noise and the pose's would only paint it again in front). None for a
        #: floor plan. There, a cell is learned after `sensed[0]` frames, not `hits_needed`.
        self.beside_static: NDArray[np.bool_] | None = None
        self.sensed = sensed
        self.resolution_m = float(resolution_m)
        self.origin_xy = (float(origin_xy[0]), float(origin_xy[1]))
        self.hits_needed = hits_needed
        self.z_range = z_range
        shape = self.static.shape
        self.hits = np.zeros(shape, np.uint16) if hits is None else hits.astype(np.uint16)
        self.seen_free = np.zeros(shape, bool)
        #: Per cell, the lowest point that hit it since its hits were last reset (m; inf:
        #: none, as for the hits of a map file, which keeps no heights: never cleared; a
        #: resumed database keeps them), and the frames in a row that saw it as floor
        #: with no hit (module docstring).
        self.low_z = np.full(shape, np.inf, np.float32)
        self.floor_run = np.zeros(shape, np.uint8)
        #: The tops layer (see the module docstring): m (0: nothing seen), frames.
        self.top_z = np.zeros(shape, np.float32) if tops is None else tops[0].astype(np.float32)
        self.top_n = np.zeros(shape, np.uint16) if tops is None else tops[1].astype(np.uint16)
        #: Counts the changes of `cells()`, so a reader can tell when the grid it holds is old.
        self.version = 0
        if self.hits.shape != shape:
            raise ValueError(f"learned layer {self.hits.shape} does not match static {shape}")

    def adopt_static(self, cells: NDArray[np.uint8], people: FloatArray | None = None) -> None:
        """A new static layer of the same geometry (the SLAM grid as it grows). The lidar
        maps whoever stood still as an obstacle: `furniture` leaves out the blobs a
        person could be (`PERSON_BLOB_M` across at most), and a blob within
        `PERSON_BLOB_M` / 2 of a mapped person (`people`, (n, 2) m) is theirs, not the
        building's: unknown (nobody saw the floor they stand on)."""
        if cells.shape != self.static.shape:
            raise ValueError(f"static layer {cells.shape} does not match {self.static.shape}")
        self.static = self._without_people(np.array(cells, dtype=np.uint8), people)
        self.static_occupied = self.static == OCCUPIED
        self.sensed_static()
        self.version += 1

    def forget_people(self, people: FloatArray) -> int:
        """A sensed static layer read back (a saved map, a map file, a resumed database)
        with the people the map has, (n, 2) m: their blobs become unknown, as
        `adopt_static` makes them; how many cells. A map saved after its last SLAM grid
        was taken kept them (the hall's shipped map: 4 of its 5 people, 46-55 cells
        each), and there the lidar's protective field left out the legs of a person
        standing at their place (`services.navigation.scan_people`, `static_margin_m`)."""
        cleared = self._without_people(self.static.copy(), people)
        n = int(np.count_nonzero(cleared != self.static))
        if n:
            self.static = cleared
            self.static_occupied = self.static == OCCUPIED
            self.version += 1
        self.sensed_static()
        return n

    def _without_people(
        self, cells: NDArray[np.uint8], people: FloatArray | None
    ) -> NDArray[np.uint8]:
        """`cells` (changed in place) with each blob (at most `PERSON_BLOB_M` across)
        within `PERSON_BLOB_M` / 2 of a person of `people` unknown."""
        if people is None or not len(people):
            return cells
        occupied = cells == OCCUPIED
        blobs = occupied & ~without_blobs(occupied, PERSON_BLOB_M / self.resolution_m)
        labels, _n = ndimage.label(blobs, structure=np.ones((3, 3), bool))
        ix, iy, inside = self.cells_of(np.asarray(people, float).reshape(-1, 2))
        reach = round(0.5 * PERSON_BLOB_M / self.resolution_m)
        theirs: set[int] = set()
        for x, y in zip(ix[inside], iy[inside], strict=True):
            window = labels[max(0, y - reach) : y + reach + 1, max(0, x - reach) : x + reach + 1]
            theirs |= set(np.unique(window[window > 0]).tolist())
        if theirs:
            cells[np.isin(labels, list(theirs))] = UNKNOWN
        return cells

    def sensed_static(self) -> None:
        """The static layer is a sensor's map (the SLAM's, a map file's), not a floor plan:
        `furniture` leaves out the blobs a person standing could have left in it, and the
        depth learns nothing beside its obstacles (`beside_static`)."""
        self.furniture = without_blobs(self.static_occupied, PERSON_BLOB_M / self.resolution_m)
        hits, clearance_m = self.sensed
        self.hits_needed = hits
        reach = round(clearance_m / self.resolution_m)
        structure = without_blobs(self.static_occupied, LEG_BLOB_M / self.resolution_m)
        self.beside_static = (
            ndimage.binary_dilation(structure, structure=np.ones((3, 3), bool), iterations=reach)
            if reach > 0
            else structure
        ) | self.static_occupied

    @classmethod
    def unknown(cls, half_extent_m: float, resolution_m: float, **kw: object) -> Occupancy:
        n = round(2 * half_extent_m / resolution_m)
        grid = np.full((n, n), UNKNOWN, np.uint8)
        return cls(grid, resolution_m, (-half_extent_m, -half_extent_m), **kw)  # type: ignore[arg-type]

    def cells_of(
        self, xy: FloatArray
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        ix = np.floor((xy[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(np.intp)
        iy = np.floor((xy[:, 1] - self.origin_xy[1]) / self.resolution_m).astype(np.intp)
        ny, nx = self.static.shape
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return ix, iy, inside

    def integrate(self, points_world: FloatArray, sees_over: SeesOver | None = None) -> int:
        """Count one depth frame's points (N, 3); the number of cells newly learned.
        `sees_over`: the frame's test of the points it sees past (module docstring;
        None: every cell's highest point is its top)."""
        if len(points_world) == 0:
            return 0
        before = self.learned_mask().sum()
        z = points_world[:, 2]
        ix, iy, inside = self.cells_of(points_world[:, :2])
        hit = inside & (z >= self.z_range[0]) & (z <= self.z_range[1])
        nx = self.static.shape[1]
        hit_flat = iy[hit] * nx + ix[hit]
        flat = np.unique(hit_flat)
        counts = self.hits.reshape(-1)
        counts[flat] = np.minimum(counts[flat].astype(np.int64) + 1, 60000).astype(np.uint16)
        np.minimum.at(self.low_z.reshape(-1), hit_flat, z[hit].astype(np.float32))
        self._tops(hit_flat, points_world[hit], sees_over)
        floor = inside & (np.abs(z) < FLOOR_Z_M)
        free = np.unique(iy[floor] * nx + ix[floor])
        seen = self.seen_free.reshape(-1)
        opened = bool(np.any(~seen[free] & (self.static.reshape(-1)[free] == UNKNOWN)))
        seen[free] = True
        cleared = self._clear(flat, np.setdiff1d(free, flat, assume_unique=True))
        learned = int(self.learned_mask().sum() - before)
        if learned or opened or cleared:
            self.version += 1
        return learned

    def _clear(self, hit: NDArray[np.intp], floor_only: NDArray[np.intp]) -> int:
        """One frame's floor evidence (module docstring): the cells it hit restart their
        count, those it saw only as floor add to it; how many cells' hits it reset."""
        run, counts = self.floor_run.reshape(-1), self.hits.reshape(-1)
        run[hit] = 0
        run[floor_only] = np.minimum(run[floor_only].astype(np.int64) + 1, 255)
        low = self.low_z.reshape(-1)
        due = floor_only[
            (run[floor_only] >= CLEAR_FRAMES)
            & (counts[floor_only] > 0)
            & (low[floor_only] < LOW_HIT_M)
        ]
        counts[due], run[due], low[due] = 0, 0, np.inf
        return len(due)

    def _tops(self, flat: NDArray[np.intp], xyz: FloatArray, sees_over: SeesOver | None) -> None:
        """One frame's highest point per cell against the cells' running tops (of the
        cells it saw over, with `sees_over`)."""
        if len(flat) == 0:
            return
        order = np.lexsort((-xyz[:, 2], flat))  # by cell, each one's highest point first
        cells, first = np.unique(flat[order], return_index=True)
        highest = xyz[order[first]]
        if sees_over is not None:
            over = sees_over(highest + np.array([0.0, 0.0, OVER_M]))
            cells, highest = cells[over], highest[over]
        seen = highest[:, 2].astype(np.float32)
        tz, tn = self.top_z.reshape(-1), self.top_n.reshape(-1)
        higher = seen > tz[cells] + TOP_TOL_M
        same = ~higher & (seen >= tz[cells] - TOP_TOL_M)
        tz[cells[higher]] = seen[higher]
        tn[cells[higher]] = 1
        tn[cells[same]] = np.minimum(tn[cells[same]].astype(np.int64) + 1, 60000)

    def learned_mask(self, window: tuple[slice, slice] | None = None) -> NDArray[np.bool_]:
        w = window or (slice(None), slice(None))
        learned = (self.hits[w] >= self.hits_needed) & (self.static[w] != OCCUPIED)
        if self.beside_static is not None:
            learned &= ~self.beside_static[w]
        return np.asarray(learned, bool)

    def cells(self, window: tuple[slice, slice] | None = None) -> NDArray[np.uint8]:
        """The merged grid (of a window of rows and columns): static, unknown cells seen
        as floor made free, learned obstacles."""
        w = window or (slice(None), slice(None))
        out = self.static[w].copy()
        out[(out == UNKNOWN) & self.seen_free[w]] = FREE
        out[self.learned_mask(w)] = OCCUPIED
        return out

    def occupied_at(self, xy: FloatArray) -> NDArray[np.bool_]:
        ix, iy, inside = self.cells_of(np.atleast_2d(xy))
        grid = self.cells()
        out = np.ones(len(ix), bool)
        out[inside] = grid[iy[inside], ix[inside]] == OCCUPIED
        return out
