"""Seeded furniture layouts: the hall's walls, racks, benches, tables, machines and pallets.

A layout is placed item by item by rejection sampling from one `numpy.random.Generator`:
an item is kept when its floor rectangle keeps an aisle (`AISLE_M`, wider in front of the
tables and benches the robot works at) from every other item. Items that stand against a
wall (racks, benches, partitions) are exempt from the aisle to that wall only. Pairwise
aisles wider than the robot make the free floor one connected region by construction;
`feasibility.check_paths` verifies it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from common.messages.world import Hall, Obstacle, ObstacleKind, Rgba, SupportSurface
from services.sim.appearance import (
    BENCH_COLOURS,
    MACHINE_COLOURS,
    PALLET_COLOURS,
    RACK_COLOURS,
    TABLE_COLOURS,
    WALL_COLOURS,
    colour,
    uniform,
)
from services.sim.feasibility import box_corners

#: Free gap kept between any two items, m.
AISLE_M = 1.3
#: Free gap kept around tables and benches, where the robot stands to pick, m.
WORK_AISLE_M = 1.7
#: Wall thickness, m.
WALL_M = 0.2


class Layout(NamedTuple):
    """A hall's interior, its obstacles and the support surfaces among them."""

    hall: Hall
    obstacles: tuple[Obstacle, ...]
    surfaces: tuple[SupportSurface, ...]


class _Item(NamedTuple):
    obstacle: Obstacle
    corners: NDArray[np.float64]
    side: int | None  # the wall side it stands against, None when free-standing
    perimeter: bool  # a perimeter wall segment


def _overlap(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """Separating-axis test for two convex polygons (k, 2)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for nx, ny in zip(-edges[:, 1], edges[:, 0], strict=True):
            pa, pb = a @ (nx, ny), b @ (nx, ny)
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def _point_to_edges(points: NDArray[np.float64], poly: NDArray[np.float64]) -> float:
    """The smallest distance from any of `points` (k, 2) to the edges of `poly` (m, 2)."""
    seg = np.roll(poly, -1, axis=0) - poly
    d = points[:, None, :] - poly[None, :, :]
    t = np.clip(np.einsum("kmi,mi->km", d, seg) / np.einsum("mi,mi->m", seg, seg), 0.0, 1.0)
    diff = d - t[..., None] * seg
    return float(np.sqrt(np.min(np.einsum("kmi,kmi->km", diff, diff))))


def rect_gap(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """The floor distance between two convex polygons (k, 2); 0 when they overlap."""
    if _overlap(a, b):
        return 0.0
    return min(_point_to_edges(a, b), _point_to_edges(b, a))


def _bound_gap(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """A lower bound of `rect_gap` from bounding circles: cheap, and enough for far pairs."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    ra = float(np.max(np.linalg.norm(a - ca, axis=1)))
    rb = float(np.max(np.linalg.norm(b - cb, axis=1)))
    return float(np.linalg.norm(ca - cb)) - ra - rb


def _aisle(kind: str) -> float:
    return WORK_AISLE_M if kind in ("table", "bench") else AISLE_M


class _Placer:
    """The items placed so far, the hall's wall sides and its door openings."""

    def __init__(self, hall: Hall) -> None:
        self.hall = hall
        self.items: list[_Item] = []
        self.counts: dict[str, int] = {}
        self.openings: list[tuple[int, float, float]] = []  # side, along from, along to
        x0, y0 = hall.min_xy
        x1, y1 = hall.max_xy
        # Per side 0..3 (bottom, right, top, left): inner-face midpoint and length.
        self.faces = (
            ((0.5 * (x0 + x1), y0), x1 - x0),
            ((x1, 0.5 * (y0 + y1)), y1 - y0),
            ((0.5 * (x0 + x1), y1), x1 - x0),
            ((x0, 0.5 * (y0 + y1)), y1 - y0),
        )

    def fits(self, kind: str, corners: NDArray[np.float64], side: int | None) -> bool:
        lo, hi = np.array(self.hall.min_xy), np.array(self.hall.max_xy)
        if np.any(corners < lo - 1e-6) or np.any(corners > hi + 1e-6):
            return False
        for item in self.items:
            if item.perimeter and item.side == side:
                continue  # an item stands against its own wall
            need = AISLE_M if item.perimeter else max(_aisle(kind), _aisle(item.obstacle.kind))
            if _bound_gap(corners, item.corners) < need and rect_gap(corners, item.corners) < need:
                return False
        return True

    def add(
        self,
        kind: ObstacleKind,
        centre_xy: tuple[float, float],
        half_size: tuple[float, float, float],
        yaw: float,
        rgba: Rgba,
        side: int | None = None,
        perimeter: bool = False,
    ) -> Obstacle | None:
        """Place an obstacle standing on the floor if it fits; None when it does not."""
        corners = box_corners(centre_xy, half_size[:2], yaw)
        if not perimeter and not self.fits(kind, corners, side):
            return None
        n = self.counts.get(kind, 0) + 1
        self.counts[kind] = n
        obstacle = Obstacle(
            id=f"{kind}_{n}",
            kind=kind,
            centre=(float(centre_xy[0]), float(centre_xy[1]), float(half_size[2])),
            half_size=(float(half_size[0]), float(half_size[1]), float(half_size[2])),
            yaw=float(math.remainder(yaw, math.tau)),
            rgba=rgba,
        )
        self.items.append(_Item(obstacle, corners, side, perimeter))
        return obstacle

    def perimeter(self, rng: np.random.Generator, rgba: Rgba, openings: bool) -> None:
        """The four walls, each with at most one door opening."""
        for side, (face, length) in enumerate(self.faces):
            yaw = side * math.pi / 2
            along = np.array([math.cos(yaw), math.sin(yaw)])
            inward = np.array([-along[1], along[0]])
            lo, hi = -0.5 * length - WALL_M, 0.5 * length + WALL_M
            spans = [(lo, hi)]
            if openings and rng.random() < 0.5:
                width = uniform(rng, 2.5, 4.0)
                start = uniform(rng, -0.5 * length + 1.5, 0.5 * length - 1.5 - width)
                spans = [(lo, start), (start + width, hi)]
                self.openings.append((side, start, start + width))
            for a, b in spans:
                mid = np.asarray(face) + along * 0.5 * (a + b) - inward * 0.5 * WALL_M
                half = (0.5 * (b - a), 0.5 * WALL_M, 0.5 * self.hall.wall_height)
                self.add("wall", (mid[0], mid[1]), half, yaw, rgba, side=side, perimeter=True)

    def against_wall(
        self,
        rng: np.random.Generator,
        kind: ObstacleKind,
        length: float,
        depth: float,
        height: float,
        rgba: Rgba,
        gap: float = 0.05,
        tries: int = 40,
    ) -> Obstacle | None:
        """An item with its back to a random wall, its length along it (local +y inward)."""
        for _ in range(tries):
            side = int(rng.integers(4))
            face, wall_length = self.faces[side]
            a = uniform(rng, -0.5 * wall_length + 0.5 * length, 0.5 * wall_length - 0.5 * length)
            if any(
                s == side and a0 - 0.5 < a + 0.5 * length and a - 0.5 * length < a1 + 0.5
                for s, a0, a1 in self.openings
            ):
                continue
            yaw = side * math.pi / 2
            along = np.array([math.cos(yaw), math.sin(yaw)])
            inward = np.array([-along[1], along[0]])
            centre = np.asarray(face) + along * a + inward * (gap + 0.5 * depth)
            half = (0.5 * length, 0.5 * depth, 0.5 * height)
            placed = self.add(kind, (centre[0], centre[1]), half, yaw, rgba, side=side)
            if placed is not None:
                return placed
        return None

    def free_standing(
        self,
        rng: np.random.Generator,
        kind: ObstacleKind,
        half_size: tuple[float, float, float],
        rgba: Rgba,
        yaw_jitter: float = 0.0,
        tries: int = 60,
    ) -> Obstacle | None:
        """An item anywhere on the floor, turned by a multiple of 90 degrees plus jitter."""
        (x0, y0), (x1, y1) = self.hall.min_xy, self.hall.max_xy
        reach = math.hypot(half_size[0], half_size[1])
        for _ in range(tries):
            centre = (uniform(rng, x0 + reach, x1 - reach), uniform(rng, y0 + reach, y1 - reach))
            yaw = int(rng.integers(4)) * math.pi / 2 + uniform(rng, -yaw_jitter, yaw_jitter)
            placed = self.add(kind, centre, half_size, yaw, rgba)
            if placed is not None:
                return placed
        return None


def surface_of(obstacle: Obstacle) -> SupportSurface:
    """The top of a table or bench."""
    return SupportSurface(
        id=obstacle.id,
        centre_xy=(obstacle.centre[0], obstacle.centre[1]),
        half_extents=(obstacle.half_size[0], obstacle.half_size[1]),
        yaw=obstacle.yaw,
        top_height=obstacle.centre[2] + obstacle.half_size[2],
    )


def _layout(placer: _Placer) -> Layout:
    obstacles = tuple(item.obstacle for item in placer.items)
    surfaces = tuple(surface_of(o) for o in obstacles if o.kind in ("table", "bench"))
    return Layout(placer.hall, obstacles, surfaces)


def _hall(size_x: float, size_y: float, wall_height: float) -> Hall:
    half_x, half_y = 0.5 * float(size_x), 0.5 * float(size_y)
    return Hall((-half_x, -half_y), (half_x, half_y), float(wall_height))


def hall_layout(rng: np.random.Generator) -> Layout:
    """An industrial hall of about 20 x 15 m: walls with doors, partitions and furniture."""
    placer = _Placer(
        _hall(uniform(rng, 19.0, 21.0), uniform(rng, 14.0, 16.0), uniform(rng, 3, 4.5))
    )
    wall_rgba = colour(rng, WALL_COLOURS)
    placer.perimeter(rng, wall_rgba, openings=True)
    for _ in range(int(rng.integers(1, 3))):
        length = uniform(rng, 3.0, 5.5)
        placer.against_wall(rng, "wall", 0.15, length, uniform(rng, 2.2, 3.0), wall_rgba, gap=0)
    for _ in range(int(rng.integers(2, 5))):
        dims = uniform(rng, 2.5, 4.5), uniform(rng, 0.6, 1.0), uniform(rng, 2.0, 3.0)
        placer.against_wall(rng, "rack", *dims, colour(rng, RACK_COLOURS))
    for _ in range(int(rng.integers(1, 3))):
        dims = uniform(rng, 1.5, 2.4), uniform(rng, 0.6, 0.8), uniform(rng, 0.85, 0.95)
        placer.against_wall(rng, "bench", *dims, colour(rng, BENCH_COLOURS))
    for _ in range(int(rng.integers(2, 4))):
        half = (
            0.5 * uniform(rng, 1.2, 2.0),
            0.5 * uniform(rng, 0.7, 0.9),
            0.5 * uniform(rng, 0.7, 0.85),
        )
        placer.free_standing(rng, "table", half, colour(rng, TABLE_COLOURS), yaw_jitter=0.2)
    for _ in range(int(rng.integers(1, 4))):
        half = (
            0.5 * uniform(rng, 1.0, 2.4),
            0.5 * uniform(rng, 1.0, 2.0),
            0.5 * uniform(rng, 1.2, 2.2),
        )
        placer.free_standing(rng, "machine", half, colour(rng, MACHINE_COLOURS))
    for _ in range(int(rng.integers(2, 5))):
        half = 0.6, 0.4, 0.5 * uniform(rng, 0.15, 1.4)
        placer.free_standing(rng, "pallet", half, colour(rng, PALLET_COLOURS), yaw_jitter=0.1)
    return _layout(placer)


def small_layout(rng: np.random.Generator) -> Layout:
    """A closed room of about 8 x 6 m with one table, its long side facing -x."""
    placer = _Placer(_hall(uniform(rng, 7.5, 8.5), uniform(rng, 5.5, 6.5), uniform(rng, 2.5, 3.0)))
    placer.perimeter(rng, colour(rng, WALL_COLOURS), openings=False)
    x = placer.hall.max_xy[0] - uniform(rng, 1.8, 2.4)
    half = (
        0.5 * uniform(rng, 1.2, 1.6),
        0.5 * uniform(rng, 0.7, 0.8),
        0.5 * uniform(rng, 0.72, 0.85),
    )
    yaw = 0.5 * math.pi + uniform(rng, -0.1, 0.1)  # local +y, the front edge, faces -x
    table = placer.add("table", (x, uniform(rng, -0.5, 0.5)), half, yaw, colour(rng, TABLE_COLOURS))
    if table is None:
        raise RuntimeError("the small world's table does not fit its room")
    return _layout(placer)
