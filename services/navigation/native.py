"""The grid search itself: A* in C (built at install), or scipy's Dijkstra without a compiler.

`search(cost, start, goal, weight)` finds the cheapest 8-connected path on a cost grid
(`cost < 0` lethal; an edge u→v costs step · (1 + weight · (c_u + c_v) / 2), step 1 or √2
cells; no diagonal past a lethal cell). The C source (`astar.c`, plain C99, no Python
headers) is built by the install (`setup.py`: an optional setuptools extension,
`services/navigation/_astar*.so`) and loaded with ctypes: a pure-Python A* is ~100×
too slow for 640 k cells. Nothing compiles at run time. Without a compiler the same
graph goes to `scipy.sparse.csgraph.dijkstra` (exact, slower); `grid_graph` is also the
independent reference the unit tests compare A* against.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import logging
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

log = logging.getLogger(__name__)

_OFFSETS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


class SearchResult(NamedTuple):
    """cells: (n, 2) int (iy, ix) from start to goal, empty when there is no path.
    cost: the path's cost in cell units (inf without a path). expanded: nodes closed."""

    cells: NDArray[np.int64]
    cost: float
    expanded: int


@functools.cache
def _library() -> ctypes.CDLL | None:
    """The compiled search, or None when the install built none (logged once)."""
    spec = importlib.util.find_spec(f"{__package__}._astar")
    if spec is None or spec.origin is None:
        log.warning("the C grid search was not built at install: planning with scipy (slower)")
        return None
    lib = spec.origin
    dll = ctypes.CDLL(lib)
    f = dll.astar
    f.restype = ctypes.c_long
    f.argtypes = [
        ctypes.c_int,
        ctypes.c_int,
        ctypes.c_void_p,
        ctypes.c_double,
        ctypes.c_int,
        ctypes.c_int,
        ctypes.c_int,
        ctypes.c_void_p,
        ctypes.c_long,
        ctypes.POINTER(ctypes.c_double),
        ctypes.POINTER(ctypes.c_long),
    ]
    return dll


def compiled() -> bool:
    """Whether the C search is in use."""
    return _library() is not None


def search(
    cost: NDArray[np.float32],
    start: tuple[int, int],
    goal: tuple[int, int],
    weight: float,
    heuristic: bool = True,
) -> SearchResult:
    """The cheapest path from start to goal (cells (iy, ix)); A*, or Dijkstra without heuristic."""
    grid = np.ascontiguousarray(cost, dtype=np.float32)
    ny, nx = grid.shape
    s, g = start[0] * nx + start[1], goal[0] * nx + goal[1]
    lib = _library()
    if lib is None:
        return _scipy_search(grid, s, g, weight)
    path = np.empty(ny * nx, dtype=np.int32)
    out_cost, expanded = ctypes.c_double(math.inf), ctypes.c_long(0)
    n = lib.astar(
        ny, nx, grid.ctypes.data, weight, s, g, int(heuristic), path.ctypes.data, path.size,
        ctypes.byref(out_cost), ctypes.byref(expanded),
    )  # fmt: skip
    if n == -3:
        raise MemoryError(f"A* on a {ny}×{nx} grid ran out of memory")
    if n < 0:
        return SearchResult(np.empty((0, 2), dtype=np.int64), math.inf, int(expanded.value))
    flat = path[:n][::-1].astype(np.int64)
    cells = np.stack([flat // nx, flat % nx], axis=1)
    return SearchResult(cells, float(out_cost.value), int(expanded.value))


def grid_graph(cost: NDArray[np.float32], weight: float) -> csr_matrix:
    """The search's graph as a sparse matrix (the same edges and weights as `astar.c`)."""
    ny, nx = cost.shape
    c = np.asarray(cost, dtype=np.float64)
    idx = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, data = [], [], []
    for dy, dx in _OFFSETS:
        ys = slice(max(0, -dy), ny - max(0, dy))
        xs = slice(max(0, -dx), nx - max(0, dx))
        yt = slice(max(0, dy), ny - max(0, -dy))
        xt = slice(max(0, dx), nx - max(0, -dx))
        ok = (c[ys, xs] >= 0) & (c[yt, xt] >= 0)
        if dy and dx:  # no corner cutting past a lethal cell
            ok &= (c[ys, xt] >= 0) & (c[yt, xs] >= 0)
        step = math.sqrt(2.0) if dy and dx else 1.0
        w = step * (1.0 + weight * 0.5 * (c[ys, xs] + c[yt, xt]))
        rows.append(idx[ys, xs][ok])
        cols.append(idx[yt, xt][ok])
        data.append(w[ok])
    r, k, d = np.concatenate(rows), np.concatenate(cols), np.concatenate(data)
    return csr_matrix((d, (r, k)), shape=(ny * nx, ny * nx))


def _scipy_search(cost: NDArray[np.float32], s: int, g: int, weight: float) -> SearchResult:
    nx = cost.shape[1]
    if cost.flat[s] < 0 or cost.flat[g] < 0:
        return SearchResult(np.empty((0, 2), dtype=np.int64), math.inf, 0)
    dist, pred = dijkstra(grid_graph(cost, weight), indices=s, return_predecessors=True)
    if not math.isfinite(dist[g]):
        return SearchResult(np.empty((0, 2), dtype=np.int64), math.inf, int(np.sum(dist < dist[g])))
    flat = [g]
    while flat[-1] != s:
        flat.append(int(pred[flat[-1]]))
    arr = np.array(flat[::-1], dtype=np.int64)
    return SearchResult(np.stack([arr // nx, arr % nx], axis=1), float(dist[g]), len(dist))
