"""The mapping patrol's route: viewpoints covering the free space of an occupancy grid.

`coverage_route` puts viewpoints on a lattice of `spacing_m` over the free space that
keeps `clearance_m` from every obstacle and is connected to the start, visits them
nearest-first, and joins them with shortest 8-connected paths (Dijkstra on a 10 cm grid).
`targets` are places that must be seen from within `see_m` (the tops of the floor plan's
tables and benches, `support_targets`: the network finds a can there from 2 m, and the
lattice leaves bench tops 2.2-2.3 m from every viewpoint in the hall): each target the
lattice leaves farther gets the reachable cell nearest to it as a viewpoint of its own,
when that cell is within `see_m`.

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
from common.messages.world import OCCUPIED, SupportSurface

PLAN_RES_M = 0.1


@dataclass(frozen=True)
class Route:
    """Viewpoints (k, 2) and, per leg, the path to it (m, 2), in the world frame."""

    viewpoints: list[FloatArray]
    paths: list[FloatArray]


def _coarsen(cells: NDArray[np.uint8], factor: int) -> NDArray[np.bool_]:
    ny, nx = (cells.shape[0] // factor) * factor, (cells.shape[1] // factor) * factor
    occ = cells[:ny, :nx] == OCCUPIED
    return occ.reshape(ny // factor, factor, nx // factor, factor).any(axis=(1, 3))


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
    factor = max(1, round(PLAN_RES_M / resolution_m))
    res = resolution_m * factor
    occ = _coarsen(cells, factor)
    safe = ndimage.distance_transform_edt(~occ) * res > clearance_m
    ox, oy = origin_xy

    def cell(xy: tuple[float, float] | FloatArray) -> tuple[int, int]:
        return int((xy[1] - oy) / res), int((xy[0] - ox) / res)

    def centre(iy: int, ix: int) -> FloatArray:
        return np.array([ox + (ix + 0.5) * res, oy + (iy + 0.5) * res])

    labels, _n = ndimage.label(safe, structure=np.ones((3, 3)))
    sy, sx = cell(start_xy)
    iy_all, ix_all = np.nonzero(safe)
    if len(iy_all) == 0:
        return Route([], [])
    if not (0 <= sy < safe.shape[0] and 0 <= sx < safe.shape[1] and safe[sy, sx]):
        k = int(np.argmin((iy_all - sy) ** 2 + (ix_all - sx) ** 2))
        sy, sx = int(iy_all[k]), int(ix_all[k])
    reach = labels == labels[sy, sx]
    step = max(1, round(spacing_m / res))
    lattice = np.zeros_like(reach)
    lattice[step // 2 :: step, step // 2 :: step] = True
    cand = [(int(a), int(b)) for a, b in zip(*np.nonzero(reach & lattice), strict=True)]
    if targets is not None and len(targets):
        cand += _viewpoints_for(targets, cand, np.argwhere(reach), centre, see_m)
    graph, index, ys, xs = grid_graph(reach, res)
    viewpoints, paths = [], []
    here = (sy, sx)
    todo = set(cand)
    while todo:
        dist, pred = dijkstra(graph, directed=False, indices=index[here], return_predecessors=True)
        nxt = min(todo, key=lambda c: (dist[index[c]], c))
        todo.discard(nxt)
        if not np.isfinite(dist[index[nxt]]):
            continue
        chain = [int(index[nxt])]
        while chain[-1] != index[here]:
            chain.append(int(pred[chain[-1]]))
        chain.reverse()
        paths.append(np.array([centre(int(ys[i]), int(xs[i])) for i in chain]))
        viewpoints.append(centre(*nxt))
        here = nxt
    return Route(viewpoints, paths)


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
