"""The costmap: static occupancy inflated by the footprint, a short-lived obstacle layer
and a people layer, combined into one cost grid for the planner and the controller.

Costs are float32 per cell: −1 lethal, else [0, 1] (what the planner adds, scaled by its
weight, to each metre). Inflation is by distance from the cell centre to the nearest
obstacle cell centre (`scipy.ndimage.distance_transform_edt`): closer than the
footprint's half width plus `lethal_margin_m` is lethal (the robot's centreline may not
go there: it walks along its path, so its width is what must fit), then the cost decays
exponentially until `inflation_m`. The static and short-lived layers are inflated
together; a person is a disc, lethal within `person_lethal_m` of the base origin, with a
cost that falls to zero at `person_cost_m`. The short-lived layer remembers when each cell
was last seen occupied (`ObstacleLayer`): marks expire after `navigation.obstacle_ttl_s`,
and a cell seen through (`clear`) is forgotten at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from services.navigation.grid import BoolGrid, FloatGrid, Footprint, Grid

CostGrid = NDArray[np.float32]
LETHAL = np.float32(-1.0)


@dataclass(frozen=True)
class CostParams:
    """Inflation and the people layer (see the module docstring), distances in m, decay
    per m. Not settings: the costmap's shape, tuned with the footprint and the planner."""

    lethal_margin_m: float = 0.06
    inflation_m: float = 1.0
    decay_per_m: float = 4.0
    person_lethal_m: float = 0.85
    person_cost_m: float = 2.0


@dataclass(frozen=True)
class Person:
    """A person on the floor: id, position (m, world), yaw (rad; None when unknown), floor
    velocity (m/s, world; None while not known: a person just seen), and when they were
    last seen there (sim ns; None: now, or not known: a seen or scanned person's)."""

    id: str
    x: float
    y: float
    yaw: float | None = None
    velocity: tuple[float, float] | None = (0.0, 0.0)
    seen_ns: int | None = None


def clearance(occupied: BoolGrid, resolution: float) -> FloatGrid:
    """Distance (ny, nx) in m from each cell centre to the nearest occupied one.

    Outside the grid counts as occupied.
    """
    padded = np.pad(~occupied, 1, constant_values=False)
    dist: FloatGrid = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * resolution
    return dist


def inflate(dist: FloatGrid, fp: Footprint, p: CostParams) -> CostGrid:
    """Costs from clearances: lethal within the half width + margin, then decaying."""
    lethal_r = fp.half_width + p.lethal_margin_m
    beyond = dist - lethal_r
    cost = np.where(beyond < p.inflation_m, np.exp(-p.decay_per_m * np.maximum(beyond, 0.0)), 0.0)
    out = cost.astype(np.float32)
    out[dist < lethal_r] = LETHAL
    return out


def people_cost(grid: Grid, people: list[Person], p: CostParams) -> CostGrid:
    """The people layer: lethal discs and their decaying cost, 0 elsewhere."""
    ny, nx = grid.shape
    out = np.zeros((ny, nx), dtype=np.float32)
    res = grid.resolution
    for person in people:
        r = p.person_cost_m
        ix0 = max(0, int((person.x - r - grid.origin[0]) / res))
        ix1 = min(nx, int((person.x + r - grid.origin[0]) / res) + 1)
        iy0 = max(0, int((person.y - r - grid.origin[1]) / res))
        iy1 = min(ny, int((person.y + r - grid.origin[1]) / res) + 1)
        if ix0 >= ix1 or iy0 >= iy1:
            continue
        xs = grid.origin[0] + (np.arange(ix0, ix1) + 0.5) * res
        ys = grid.origin[1] + (np.arange(iy0, iy1) + 0.5) * res
        d = np.hypot(xs[None, :] - person.x, ys[:, None] - person.y)
        span = max(p.person_cost_m - p.person_lethal_m, 1e-6)
        c = np.clip((p.person_cost_m - d) / span, 0.0, 1.0).astype(np.float32)
        window = out[iy0:iy1, ix0:ix1]
        np.maximum(window, c, out=window, where=window >= 0)
        window[d < p.person_lethal_m] = LETHAL
    return out


def combine(*layers: CostGrid) -> CostGrid:
    """Cell-wise maximum, lethal anywhere is lethal."""
    out = np.maximum.reduce(layers)
    lethal = np.logical_or.reduce([layer < 0 for layer in layers])
    out[lethal] = LETHAL
    return out


class ObstacleLayer:
    """Short-lived obstacles: when each cell was last seen occupied (ns; −1 never)."""

    def __init__(self, shape: tuple[int, int], ttl_ns: int) -> None:
        self.seen_ns = np.full(shape, -1, dtype=np.int64)
        self.ttl_ns = ttl_ns

    def mark(self, iy: NDArray[np.int64], ix: NDArray[np.int64], t_ns: int) -> None:
        self.seen_ns[iy, ix] = t_ns

    def clear(self, iy: NDArray[np.int64], ix: NDArray[np.int64]) -> None:
        self.seen_ns[iy, ix] = -1

    def clear_all(self) -> None:
        self.seen_ns[:] = -1

    def active(self, t_ns: int) -> BoolGrid:
        mask: BoolGrid = (self.seen_ns >= 0) & (t_ns - self.seen_ns <= self.ttl_ns)
        return mask


@dataclass(frozen=True)
class Costmap:
    """The combined costs with what they came from; `cost[iy, ix]` as the module says.

    occupied: static ∪ short-lived obstacle cells (for footprint checks; the static layer
    counts its unknown cells: the robot never walks where nobody looked).
    clearance: m from each cell to the nearest of them.
    solid: what is known to be there, the static layer's occupied cells (not its unknown
    ones) ∪ the short-lived ones: what a body swinging round can hit (the body guard).
    """

    grid: Grid
    cost: CostGrid
    occupied: BoolGrid
    clearance: FloatGrid
    people: tuple[Person, ...]
    solid: BoolGrid

    def cost_at(self, x: float, y: float) -> float:
        cell = self.grid.cell(x, y)
        return float(LETHAL) if cell is None else float(self.cost[cell])


def build_costmap(
    grid: Grid,
    fp: Footprint,
    params: CostParams,
    obstacles: BoolGrid | None = None,
    people: list[Person] | None = None,
) -> Costmap:
    """Static grid + short-lived obstacle cells + people → one costmap."""
    occupied = grid.occupied if obstacles is None else (grid.occupied | obstacles)
    solid = grid.known_occupied if obstacles is None else (grid.known_occupied | obstacles)
    dist = clearance(occupied, grid.resolution)
    cost = inflate(dist, fp, params)
    if people:
        cost = combine(cost, people_cost(grid, people, params))
    return Costmap(grid, cost, occupied, dist, tuple(people or ()), solid)
