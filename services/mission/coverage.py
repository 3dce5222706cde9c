"""The mapping patrol's routes: viewpoints over the free space, or facing the surfaces.

Both plan on the known free floor only (a cell the map does not know is no floor:
navigation plans through none) that keeps `clearance_m` from every obstacle and unknown
cell and is connected to the start, visit their viewpoints nearest-first, and join them
with shortest 8-connected paths (Dijkstra on a 10 cm grid).

`coverage_route` puts viewpoints on a lattice of `spacing_m` over the free space that
keeps `clearance_m` from every obstacle and is connected to the start, visits them
nearest-first, and joins them with shortest 8-connected paths (Dijkstra on a 10 cm grid).
`targets` are places that must be seen from within `see_m` (the tops of the floor plan's
tables and benches, `support_targets`: the network finds a can there from 2 m, and the
lattice leaves bench tops 2.2-2.3 m from every viewpoint in the hall): each target the
lattice leaves farther gets the reachable cell nearest to it as a viewpoint of its own,
when that cell is within `see_m`.

`facing_route` is the semantic pass over an explored map: artifacts stand on tables,
benches and pallets, so it looks at those only. Its viewpoints cover the surfaces'
targets (`support_targets`) greedily: each is the pose (a cell and a facing) that sees the
most targets not yet seen, where a target is seen from between `near_m` and `see_m`,
within `half_fov` of the facing, with no occupied cell on the line of sight short of the
surface (the last `SURFACE_SKIP_M`); ties go to the nearer view. Each viewpoint faces its
targets' mean bearing, and the pass looks from there without turning round: on the
hall of seed 1's partial map it is 13 viewpoints, where the lattice over the known floor
has 36 (each with three turns). The second look covers the artifacts in doubt so.
Given `busy` (places people walk or stand, the map's people's usual places), a viewpoint
stands out of their way where one can: cells within `busy_m` of a busy place serve only
the targets no other cell sees. A robot parked in an aisle is in everyone's way, and
everyone in its: hall seed 4's shift looked for a moved can from a viewpoint 0.5 m off
the end of a worker's walk and lost 140 s to four workers passing it (their separation
stops, a standoff, recoveries), where the same table is seen from 2 m out of the aisle.

Pure: the grid is the semantic map's (`dume/map/occupancy`, cells 0 free, 100 occupied,
255 unknown), the targets its floor plan's supports (`dume/map/supports`); the patrol
(`services.mission.patrol`) walks the route through navigation (`patrol_goals`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra

from common.geometry import FloatArray
from common.messages.world import FREE, OCCUPIED, SupportSurface

PLAN_RES_M = 0.1


#: A surface's own cells do not block the sight of its targets: the last this of the line.
SURFACE_SKIP_M = 0.5


@dataclass(frozen=True)
class Route:
    """Viewpoints (k, 2) and, per leg, the path to it (m, 2), in the world frame; with
    `facings`, the yaw to face at each viewpoint (a surface pass), and `unseen`: the
    targets no reachable viewpoint sees."""

    viewpoints: list[FloatArray]
    paths: list[FloatArray]
    facings: list[float] | None = None
    unseen: int = 0


def _coarsen(mask: NDArray[np.bool_], factor: int) -> NDArray[np.bool_]:
    """Blocks of `factor` × `factor` cells holding any cell of `mask`."""
    ny, nx = (mask.shape[0] // factor) * factor, (mask.shape[1] // factor) * factor
    blocks = mask[:ny, :nx].reshape(ny // factor, factor, nx // factor, factor)
    return np.asarray(blocks.any(axis=(1, 3)), bool)


@dataclass(frozen=True)
class _Floor:
    """The known floor clear of obstacles that the start reaches, on the planning grid."""

    reach: NDArray[np.bool_]
    occupied: NDArray[np.bool_]
    start: tuple[int, int]
    res: float
    origin: tuple[float, float]

    def centre(self, iy: int, ix: int) -> FloatArray:
        ox, oy = self.origin
        return np.array([ox + (ix + 0.5) * self.res, oy + (iy + 0.5) * self.res])


def _floor(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    start_xy: tuple[float, float],
    clearance_m: float,
) -> _Floor | None:
    factor = max(1, round(PLAN_RES_M / resolution_m))
    res = resolution_m * factor
    blocked = _coarsen(cells != FREE, factor)  # obstacles and what the map does not know
    safe = ndimage.distance_transform_edt(~blocked) * res > clearance_m
    iy_all, ix_all = np.nonzero(safe)
    if len(iy_all) == 0:
        return None
    sy, sx = int((start_xy[1] - origin_xy[1]) / res), int((start_xy[0] - origin_xy[0]) / res)
    if not (0 <= sy < safe.shape[0] and 0 <= sx < safe.shape[1] and safe[sy, sx]):
        k = int(np.argmin((iy_all - sy) ** 2 + (ix_all - sx) ** 2))
        sy, sx = int(iy_all[k]), int(ix_all[k])
    labels, _n = ndimage.label(safe, structure=np.ones((3, 3)))
    occupied = _coarsen(cells == OCCUPIED, factor)
    return _Floor(labels == labels[sy, sx], occupied, (sy, sx), res, origin_xy)


def support_targets(surfaces: Sequence[SupportSurface], step_m: float = 0.5) -> FloatArray:
    """(n, 2) points along each surface's long centre line, `step_m` apart, ends included."""
    points = []
    for sf in surfaces:
        hx, hy = sf.half_extents
        along = np.array([math.cos(sf.yaw), math.sin(sf.yaw)])
        if hy > hx:
            along, hx = np.array([-along[1], along[0]]), hy
        n = max(1, math.ceil(2 * hx / step_m)) + 1
        for t in np.linspace(-hx, hx, n):
            points.append(np.asarray(sf.centre_xy, float) + t * along)
    return np.array(points).reshape(-1, 2)


def grid_graph(
    mask: NDArray[np.bool_], res: float
) -> tuple[csr_matrix, NDArray[np.int64], NDArray[np.intp], NDArray[np.intp]]:
    """The graph of the cells of `mask`, 8-connected, edge length in m (undirected: one
    edge per pair), with each cell's node index (-1 off the mask) and the nodes' cells."""
    index = -np.ones(mask.shape, np.int64)
    ys, xs = np.nonzero(mask)
    index[ys, xs] = np.arange(len(ys))
    rows, cols, w = [], [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        y2, x2 = ys + dy, xs + dx
        ok = (y2 < mask.shape[0]) & (x2 >= 0) & (x2 < mask.shape[1])
        ok[ok] &= mask[y2[ok], x2[ok]]
        rows.append(index[ys[ok], xs[ok]])
        cols.append(index[y2[ok], x2[ok]])
        w.append(np.full(int(ok.sum()), res * math.hypot(dy, dx)))
    n = len(ys)
    graph = coo_matrix(
        (np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    return graph, index, ys, xs


def coverage_route(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    start_xy: tuple[float, float],
    spacing_m: float,
    clearance_m: float,
    targets: FloatArray | None = None,
    see_m: float = 1.6,
) -> Route:
    floor = _floor(cells, resolution_m, origin_xy, start_xy, clearance_m)
    if floor is None:
        return Route([], [])
    step = max(1, round(spacing_m / floor.res))
    lattice = np.zeros_like(floor.reach)
    lattice[step // 2 :: step, step // 2 :: step] = True
    cand = [(int(a), int(b)) for a, b in zip(*np.nonzero(floor.reach & lattice), strict=True)]
    if targets is not None and len(targets):
        cand += _viewpoints_for(targets, cand, np.argwhere(floor.reach), floor.centre, see_m)
    viewpoints, paths, _order = _walk(floor, cand)
    return Route(viewpoints, paths)


def facing_route(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    start_xy: tuple[float, float],
    targets: FloatArray,
    clearance_m: float,
    near_m: float,
    see_m: float,
    half_fov: float,
    busy: FloatArray | None = None,
    busy_m: float = 1.0,
) -> Route:
    """Viewpoints facing the targets (k, 2) (module docstring): the semantic pass's on
    the surfaces' targets, the second look's on the artifacts in doubt; out of the way of
    the `busy` places (k, 2) where one sees them."""
    floor = _floor(cells, resolution_m, origin_xy, start_xy, clearance_m)
    targets = np.asarray(targets, float).reshape(-1, 2)
    if floor is None or not len(targets):
        return Route([], [], [], len(targets))
    sees, bearing, dist, cand = _sightings(floor, targets, near_m, see_m)
    yaws = np.linspace(-math.pi, math.pi, 36, endpoint=False)
    off = np.abs(np.angle(np.exp(1j * (bearing[:, None, :] - yaws[None, :, None]))))
    cover = sees[:, None, :] & (off <= half_fov)  # (cand, yaw, target)
    left = cover.any(axis=(0, 1))
    unseen = int((~left).sum())
    quiet = _out_of_the_way(floor, cand, busy, busy_m)
    chosen: list[tuple[int, int]] = []
    facings: list[float] = []
    while left.any():
        counts = cover[:, :, left].sum(axis=2)
        if (counts * quiet[:, None]).max() > 0:
            counts = counts * quiet[:, None]  # a busy cell only for what no other sees
        best = counts.max()
        if best == 0:
            break
        # ties: the nearer view (mean distance to the targets it sees)
        ties = np.argwhere(counts == best)
        mean_d = [float(dist[c][cover[c, y] & left].mean()) for c, y in ties]
        c, y = ties[int(np.argmin(mean_d))]
        got = cover[c, y] & left
        facings.append(float(np.angle(np.exp(1j * bearing[c][got]).mean())))
        chosen.append(cand[c])
        left &= ~got
    viewpoints, paths, order = _walk(floor, chosen)
    return Route(viewpoints, paths, [facings[k] for k in order], unseen)


def _out_of_the_way(
    floor: _Floor, cand: list[tuple[int, int]], busy: FloatArray | None, busy_m: float
) -> NDArray[np.bool_]:
    """Which candidate cells lie farther than `busy_m` from every busy place (all of them
    without any)."""
    if busy is None or not len(busy) or not cand:
        return np.ones(len(cand), bool)
    xy = np.array([floor.centre(iy, ix) for iy, ix in cand])
    d = np.linalg.norm(xy[:, None, :] - np.asarray(busy, float).reshape(1, -1, 2), axis=2)
    return np.asarray(d.min(axis=1) > busy_m, bool)


def _sightings(
    floor: _Floor, targets: FloatArray, near_m: float, see_m: float
) -> tuple[NDArray[np.bool_], FloatArray, FloatArray, list[tuple[int, int]]]:
    """From the reachable cells within `see_m` of a target (every other cell): which
    targets each sees (range and line of sight), their bearings and distances, and the
    cells: (cand, target) arrays and the cells' list."""
    ys, xs = np.nonzero(floor.reach)
    keep = (ys % 2 == 0) & (xs % 2 == 0)
    ys, xs = ys[keep], xs[keep]
    xy = np.stack([floor.origin[0] + (xs + 0.5) * floor.res,
                   floor.origin[1] + (ys + 0.5) * floor.res], axis=1)  # fmt: skip
    d_all = np.linalg.norm(xy[:, None, :] - targets[None, :, :], axis=2)
    near = (d_all <= see_m).any(axis=1)
    xy, d = xy[near], d_all[near]
    cand = [(int(a), int(b)) for a, b in zip(ys[near], xs[near], strict=True)]
    delta = targets[None, :, :] - xy[:, None, :]
    bearing = np.arctan2(delta[..., 1], delta[..., 0])
    sees = (d >= near_m) & (d <= see_m)
    steps = np.linspace(0.0, 1.0, max(2, math.ceil(see_m / (0.5 * floor.res))))
    occ, ny, nx = floor.occupied, *floor.occupied.shape
    for j in range(len(targets)):
        rows = np.nonzero(sees[:, j])[0]
        if not len(rows):
            continue
        pts = xy[rows, None, :] + steps[None, :, None] * delta[rows, j, None, :]
        short = (1.0 - steps)[None, :] * d[rows, j, None] > SURFACE_SKIP_M
        iy = np.clip(((pts[..., 1] - floor.origin[1]) / floor.res).astype(int), 0, ny - 1)
        ix = np.clip(((pts[..., 0] - floor.origin[0]) / floor.res).astype(int), 0, nx - 1)
        sees[rows, j] = ~(occ[iy, ix] & short).any(axis=1)
    return sees, bearing, d, cand


def _walk(
    floor: _Floor, cand: list[tuple[int, int]]
) -> tuple[list[FloatArray], list[FloatArray], list[int]]:
    """The cells of `cand` the start reaches, nearest-first: their centres, the paths to
    them, and their indices into `cand`."""
    graph, index, ys, xs = grid_graph(floor.reach, floor.res)
    viewpoints, paths, order = [], [], []
    here = floor.start
    todo = set(range(len(cand)))
    while todo:
        dist, pred = dijkstra(graph, directed=False, indices=index[here], return_predecessors=True)
        k = min(todo, key=lambda i: (dist[index[cand[i]]], cand[i]))
        todo.discard(k)
        nxt = cand[k]
        if not np.isfinite(dist[index[nxt]]):
            continue
        chain = [int(index[nxt])]
        while chain[-1] != index[here]:
            chain.append(int(pred[chain[-1]]))
        chain.reverse()
        paths.append(np.array([floor.centre(int(ys[i]), int(xs[i])) for i in chain]))
        viewpoints.append(floor.centre(*nxt))
        order.append(k)
        here = nxt
    return viewpoints, paths, order


def _viewpoints_for(
    targets: FloatArray,
    cand: list[tuple[int, int]],
    reachable: NDArray[np.intp],
    centre: Callable[[int, int], FloatArray],
    see_m: float,
) -> list[tuple[int, int]]:
    """The cells to add so that each target is within `see_m` of a viewpoint (greedy, in
    the targets' order; a target with no reachable cell within `see_m` is left)."""
    cells_xy = np.array([centre(int(iy), int(ix)) for iy, ix in reachable])
    seen_from = [centre(*c) for c in cand]
    added: list[tuple[int, int]] = []
    for t in np.asarray(targets, float):
        if seen_from and float(np.min(np.linalg.norm(np.array(seen_from) - t, axis=1))) <= see_m:
            continue
        d = np.linalg.norm(cells_xy - t, axis=1)
        k = int(np.argmin(d))
        if d[k] <= see_m:
            added.append((int(reachable[k][0]), int(reachable[k][1])))
            seen_from.append(cells_xy[k])
    return added
