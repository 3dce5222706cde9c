"""Frontier-based exploration: where to look next for what the map does not know yet.

Pure functions over the semantic map's occupancy grid (`dume/map/occupancy`: FREE 0,
OCCUPIED 100, UNKNOWN 255; cell [iy, ix] spans origin + (i, i + 1) × res), in the world
frame, for the mission's explore job (`services.mission.explore`). `survey` is the one
entry point; the steps, each a function of its own:

1. `frontier_mask`: the known-free cells 4-adjacent to an unknown cell of an unknown
   region (4-connected) of at least `min_unknown_m2`, or one that reaches past the known
   floor; a few depth samples missed inside seen floor bound nothing. Only those of the
   floor the robot stands on count (`own_floor`: the free cells 4-connected to its own,
   once it stands on known floor): free cells behind an occupied line lead nowhere it
   can go. A wall is seen as its near face (the lidar's and the camera's hits) with a
   strip of free cells behind it where a beam ended inside the wall, next to the unknown
   beyond: in the small world the exploration walked 8 goals (31 m, 150 s) to look at
   such strips, one wall after another, and learnt nothing (the known floor stayed at
   46 m²); a far room seen over a wall is reached through its door, whose own frontier
   is on this floor.
2. `frontier_clusters`: those cells 8-connected (`ndimage.label`); clusters shorter than
   `min_frontier_m` (cells × res) dropped. Then, of the clusters left, the cells within
   `seen_m` of a place the robot already looked around from, or of a frontier point it
   already looked at from a goal (`aimed`), are dropped: what a look did not see from
   there (behind a table leg, under a bench, in a pallet's shadow) is not seen from
   nearer either, and the robot must not creep towards it goal after goal. With
   `within` (a centre and a radius), cells farther than the radius from the centre are
   dropped too: the place to map ends there (a hall's doors open on floor that goes on
   to the map's edge); with `bounds` (x0, y0, x1, y1: the site's outline the operator
   gives, in the map's frame), the cells outside it. What is left is clustered again,
   whatever its length: the rest of a long frontier is still one.
3. `reach`: path lengths (m) from the robot over the cells its base may cross, as
   navigation plans (unknown counts as occupied there): known free and at least `pass_m`
   from every occupied or unknown cell (navigation's lethal inflation), 8-connected
   (Dijkstra); and, as navigation lets a start inside the inflation leave it, every free
   cell within `ESCAPE_M` of the robot. Nothing is reachable when the robot's own cell
   is not known free: navigation plans from no such start.
4. the goal of each cluster: a reachable cell at least `clearance_m` from every occupied
   or unknown cell (the footprint turning in place there, as the patrol's viewpoints),
   between `view_m` of the cluster (the head camera sees the floor from 0.86 m ahead of
   the base, densely to about 2 m), not within `blacklist_m` of a goal that failed or
   of a place already looked around from; the cheapest by path + `NEAR_WEIGHT` × distance
   to the cluster, facing the cluster's cells within sight of it (`view_m`'s far end
   + 0.5 m). The next goal is the cluster's whose cost = path + distance − `gain` × the
   length of frontier within sight is least (a long frontier counts for what one look
   can take of it); None when no cluster has a goal.

The grid is cropped to the known cells (and the robot) plus a margin first, so the
work grows with what was explored, not with the map's extent.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse.csgraph import dijkstra

from common.messages.world import FREE, OCCUPIED
from services.mission.coverage import grid_graph

#: The map's code for a cell nobody has seen (`dume/map/occupancy`).
UNKNOWN = 255
#: Free cells within this of the robot join its start: navigation lets a start inside the
#: inflation leave it through free cells within the footprint's half width + 0.2 m.
ESCAPE_M = 0.4

#: Within a cluster, a metre nearer the frontier is worth this many metres of path: the
#: goal is as near as `view_m` allows (what the camera sees densely reaches farther past
#: it), not merely the nearest place within sight of it.
NEAR_WEIGHT = 4.0

Point = tuple[float, float]
BoolGrid = NDArray[np.bool_]
FloatGrid = NDArray[np.float64]


@dataclass(frozen=True)
class FrontierParams:
    """The exploration's choices (module docstring), distances in m, areas in m²."""

    min_frontier_m: float = 0.3
    clearance_m: float = 0.7
    pass_m: float = 0.32
    view_m: tuple[float, float] = (1.0, 2.0)
    gain: float = 0.5
    blacklist_m: float = 0.75
    seen_m: float = 1.2
    min_unknown_m2: float = 0.1


@dataclass(frozen=True)
class FrontierGoal:
    """Where to look from next: the pose (m, rad; world), the path to it over the grid,
    the cluster's length and centre, its distance from the pose, the cost, and the point
    it faces (the mean of the cluster's cells in sight)."""

    x: float
    y: float
    yaw: float
    path_m: float
    frontier_m: float
    frontier_xy: Point
    distance_m: float
    cost: float
    aim_xy: Point


@dataclass(frozen=True)
class Survey:
    """What the grid says now: the next goal (None: no reachable frontier), the clusters
    left and how many of them have a goal, the known-free area (m²), whether the robot's
    cell is known free (navigation can plan from it), and the clusters' centres."""

    goal: FrontierGoal | None
    clusters: int
    reachable: int
    known_free_m2: float
    robot_on_known: bool
    centres: list[Point]


def frontier_mask(cells: NDArray[np.uint8], res: float, min_unknown_m2: float) -> BoolGrid:
    """Known-free cells 4-adjacent to an unknown region that is no small hole (step 1;
    a region touching the grid's edge counts as large)."""
    unknown = cells == UNKNOWN
    labels, n = ndimage.label(unknown)
    if n == 0:
        return np.zeros(cells.shape, bool)
    large = np.bincount(labels.ravel(), minlength=n + 1) * res * res >= min_unknown_m2
    edge = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    large[edge] = True
    large[0] = False
    near = ndimage.binary_dilation(large[labels], structure=ndimage.generate_binary_structure(2, 1))
    return np.asarray((cells == FREE) & near, bool)


def own_floor(free: BoolGrid, start: tuple[int, int]) -> BoolGrid:
    """The known-free cells 4-connected to `start` (a free cell): the floor the robot
    stands on, without what lies beyond an occupied line (step 1)."""
    labels, _ = ndimage.label(free)
    return np.asarray(labels == labels[start], bool)


def frontier_clusters(mask: BoolGrid, res: float, min_frontier_m: float) -> list[NDArray[np.intp]]:
    """The frontier's 8-connected clusters at least `min_frontier_m` long, each as its
    cells (n, 2) (iy, ix), in label order (step 2)."""
    labels, n = ndimage.label(mask, structure=np.ones((3, 3)))
    if n == 0:
        return []
    order = np.argsort(labels.ravel(), kind="stable")
    counts = np.bincount(labels.ravel(), minlength=n + 1)
    starts = np.concatenate([[0], np.cumsum(counts)])
    nx = mask.shape[1]
    out = []
    for k in range(1, n + 1):
        if counts[k] * res < min_frontier_m:
            continue
        flat = order[starts[k] : starts[k + 1]]
        out.append(np.stack([flat // nx, flat % nx], axis=1))
    return out


def clearance(free: BoolGrid, res: float) -> FloatGrid:
    """Distance (m) from each cell centre to the nearest cell centre that is not free;
    outside the grid counts as not free."""
    padded = np.pad(free, 1, constant_values=False)
    dist: FloatGrid = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * res
    return dist


def reach(
    free: BoolGrid, clear: FloatGrid, res: float, start: tuple[int, int], pass_m: float
) -> FloatGrid:
    """Path lengths (m) from cell `start` over the cells the base may cross (step 3); inf
    where it cannot go, everywhere when `start` is not free."""
    out = np.full(free.shape, np.inf)
    sy, sx = start
    if not (0 <= sy < free.shape[0] and 0 <= sx < free.shape[1]) or not free[sy, sx]:
        return out
    r = math.ceil(ESCAPE_M / res)
    iy, ix = np.mgrid[-r : r + 1, -r : r + 1]
    disc = iy * iy + ix * ix <= r * r
    nodes = free & (clear >= pass_m)
    ys, xs = sy + iy[disc], sx + ix[disc]
    inside = (ys >= 0) & (ys < free.shape[0]) & (xs >= 0) & (xs < free.shape[1])
    ys, xs = ys[inside], xs[inside]
    nodes[ys, xs] |= free[ys, xs]
    graph, index, ny, nx = grid_graph(nodes, res)
    out[ny, nx] = dijkstra(graph, directed=False, indices=int(index[sy, sx]))
    return out


def _near(xy: NDArray[np.float64], points: Sequence[Point], radius: float) -> NDArray[np.bool_]:
    """Which of the points xy (n, 2) lie within `radius` of any of `points`."""
    out = np.zeros(len(xy), bool)
    for px, py in points:
        out |= np.hypot(xy[:, 0] - px, xy[:, 1] - py) <= radius
    return out


def survey(
    cells: NDArray[np.uint8],
    res: float,
    origin: Point,
    robot_xy: Point,
    params: FrontierParams = FrontierParams(),
    failed: Sequence[Point] = (),
    looked: Sequence[Point] = (),
    aimed: Sequence[Point] = (),
    within: tuple[Point, float] | None = None,
    bounds: tuple[float, float, float, float] | None = None,
) -> Survey:
    """The grid's frontiers and the next goal (see the module docstring): `failed` the
    goals navigation refused or failed, `looked` the places looked around from, `aimed`
    the frontier points looked at from them."""
    p = params
    known_free = float(np.count_nonzero(cells == FREE)) * res * res
    rx = math.floor((robot_xy[0] - origin[0]) / res)
    ry = math.floor((robot_xy[1] - origin[1]) / res)
    ky, kx = np.nonzero(cells != UNKNOWN)
    if len(ky) == 0:
        return Survey(None, 0, 0, known_free, False, [])
    pad = math.ceil((p.view_m[1] + p.clearance_m + 0.5) / res)
    y0 = max(0, min(int(ky.min()), ry) - pad)
    x0 = max(0, min(int(kx.min()), rx) - pad)
    y1 = min(cells.shape[0], max(int(ky.max()), ry) + pad + 1)
    x1 = min(cells.shape[1], max(int(kx.max()), rx) + pad + 1)
    sub = cells[y0:y1, x0:x1]
    ox, oy = origin[0] + x0 * res, origin[1] + y0 * res

    def centres(c: NDArray[np.intp]) -> NDArray[np.float64]:
        return np.column_stack([ox + (c[:, 1] + 0.5) * res, oy + (c[:, 0] + 0.5) * res])

    free = sub == FREE
    start = (ry - y0, rx - x0)
    on_known = bool(0 <= start[0] < free.shape[0] and 0 <= start[1] < free.shape[1]
                    and free[start])  # fmt: skip
    edge = frontier_mask(sub, res, p.min_unknown_m2)
    if on_known:
        edge &= own_floor(free, start)
    mask = np.zeros(sub.shape, bool)
    for c in frontier_clusters(edge, res, p.min_frontier_m):
        mask[c[:, 0], c[:, 1]] = True
    if (looked or aimed) and mask.any():
        fc = np.argwhere(mask)
        drop = _near(centres(fc), [*looked, *aimed], p.seen_m)
        mask[fc[drop, 0], fc[drop, 1]] = False
    if within is not None and mask.any():
        fc = np.argwhere(mask)
        drop = ~_near(centres(fc), [within[0]], within[1])
        mask[fc[drop, 0], fc[drop, 1]] = False
    if bounds is not None and mask.any():
        fc = np.argwhere(mask)
        xy = centres(fc)
        x0_, y0_, x1_, y1_ = bounds
        drop = (xy[:, 0] < x0_) | (xy[:, 0] > x1_) | (xy[:, 1] < y0_) | (xy[:, 1] > y1_)
        mask[fc[drop, 0], fc[drop, 1]] = False
    clusters = frontier_clusters(mask, res, 0.0)
    centre_list: list[Point] = []
    for c in clusters:
        m = centres(c).mean(axis=0)
        centre_list.append((float(m[0]), float(m[1])))
    if not clusters or not on_known:
        return Survey(None, len(clusters), 0, known_free, on_known, centre_list)
    clear = clearance(free, res)
    path = reach(free, clear, res, start, p.pass_m)
    cand = np.isfinite(path) & (clear >= p.clearance_m)
    if failed or looked:
        cy, cx = np.nonzero(cand)
        banned = _near(centres(np.stack([cy, cx], axis=1)), [*failed, *looked], p.blacklist_m)
        cand[cy[banned], cx[banned]] = False
    best: FrontierGoal | None = None
    reachable = 0
    for cells_k, centre in zip(clusters, centre_list, strict=True):
        goal = _goal_for(cells_k, cand, path, res, (ox, oy), p, centre)
        if goal is None:
            continue
        reachable += 1
        if best is None or goal.cost < best.cost:
            best = goal
    return Survey(best, len(clusters), reachable, known_free, on_known, centre_list)


def _goal_for(
    cluster: NDArray[np.intp],
    cand: BoolGrid,
    path: FloatGrid,
    res: float,
    origin: Point,
    p: FrontierParams,
    centre: Point,
) -> FrontierGoal | None:
    """The cluster's goal (step 4), None when no candidate cell sees it."""
    r = math.ceil(p.view_m[1] / res) + 1
    wy0, wx0 = max(0, int(cluster[:, 0].min()) - r), max(0, int(cluster[:, 1].min()) - r)
    wy1 = min(cand.shape[0], int(cluster[:, 0].max()) + r + 1)
    wx1 = min(cand.shape[1], int(cluster[:, 1].max()) + r + 1)
    away = np.ones((wy1 - wy0, wx1 - wx0), bool)
    away[cluster[:, 0] - wy0, cluster[:, 1] - wx0] = False
    dist = ndimage.distance_transform_edt(away) * res
    ok = cand[wy0:wy1, wx0:wx1] & (dist >= p.view_m[0]) & (dist <= p.view_m[1])
    if not ok.any():
        return None
    score = np.where(ok, path[wy0:wy1, wx0:wx1] + NEAR_WEIGHT * dist, np.inf)
    k = int(np.argmin(score))
    gy, gx = divmod(k, score.shape[1])
    x = origin[0] + (wx0 + gx + 0.5) * res
    y = origin[1] + (wy0 + gy + 0.5) * res
    cxy = np.column_stack([origin[0] + (cluster[:, 1] + 0.5) * res,
                           origin[1] + (cluster[:, 0] + 0.5) * res])  # fmt: skip
    seen = cxy[np.hypot(cxy[:, 0] - x, cxy[:, 1] - y) <= p.view_m[1] + 0.5]
    aim = seen.mean(axis=0)
    length = len(cluster) * res
    d = float(dist[gy, gx])
    along = float(path[wy0 + gy, wx0 + gx])
    return FrontierGoal(
        x=float(x),
        y=float(y),
        yaw=math.atan2(float(aim[1]) - y, float(aim[0]) - x),
        path_m=along,
        frontier_m=length,
        frontier_xy=centre,
        distance_m=d,
        cost=along + d - p.gain * len(seen) * res,
        aim_xy=(float(aim[0]), float(aim[1])),
    )


#: A step-out's target keeps this much more than `pass_m` from cells not free, m: the
#: unknown floor the robot stood on is behind it then, outside navigation's inflation.
STEP_OUT_MARGIN_M = 0.15


def step_out_target(
    cells: NDArray[np.uint8],
    res: float,
    origin: Point,
    robot_xy: Point,
    pass_m: float,
    body_m: float,
    reach_m: float = 2.0,
    self_m: float = 0.9,
) -> Point | None:
    """Where a robot standing on floor the map does not know can walk to straight ahead.

    Its own cells stay unknown until it leaves them (the head camera sees the floor from
    0.86 m ahead of the base, and the map leaves out depth within 0.7 m of it), so
    navigation cannot plan from there. The target: the nearest known-free cell within
    `reach_m` at least `pass_m` + `STEP_OUT_MARGIN_M` from every cell not free, whose
    straight line from the robot keeps `body_m` (the footprint's half width) from every
    occupied cell, crosses only free cells beyond `self_m` of the robot and keeps
    `body_m` from every cell not free once the robot's own cells are behind the body.
    None when there is no such cell.
    """
    r = math.ceil((reach_m + pass_m + STEP_OUT_MARGIN_M) / res) + 2
    cx = math.floor((robot_xy[0] - origin[0]) / res)
    cy = math.floor((robot_xy[1] - origin[1]) / res)
    y0, x0 = max(0, cy - r), max(0, cx - r)
    y1, x1 = min(cells.shape[0], cy + r + 1), min(cells.shape[1], cx + r + 1)
    if y0 >= y1 or x0 >= x1:
        return None
    sub = cells[y0:y1, x0:x1]
    free = sub == FREE
    clear = clearance(free, res)
    from_occupied = ndimage.distance_transform_edt(sub != OCCUPIED) * res
    ys, xs = np.mgrid[y0:y1, x0:x1]
    px, py = origin[0] + (xs + 0.5) * res, origin[1] + (ys + 0.5) * res
    d = np.hypot(px - robot_xy[0], py - robot_xy[1])
    ok = free & (clear >= pass_m + STEP_OUT_MARGIN_M) & (d <= reach_m)
    for k in np.argsort(np.where(ok, d, np.inf), axis=None, kind="stable"):
        iy, ix = divmod(int(k), sub.shape[1])
        if not ok[iy, ix]:
            break
        tx, ty = float(px[iy, ix]), float(py[iy, ix])
        n = max(2, math.ceil(2 * float(d[iy, ix]) / res))
        t = np.linspace(0.0, 1.0, n)
        sx = np.floor((robot_xy[0] + t * (tx - robot_xy[0]) - origin[0]) / res).astype(int) - x0
        sy = np.floor((robot_xy[1] + t * (ty - robot_xy[1]) - origin[1]) / res).astype(int) - y0
        inside = (sx >= 0) & (sx < sub.shape[1]) & (sy >= 0) & (sy < sub.shape[0])
        if not inside.all() or (from_occupied[sy, sx] < body_m).any():
            continue
        along = t * float(d[iy, ix])
        if not free[sy[along > self_m], sx[along > self_m]].all():
            continue
        clear_of = along > self_m + body_m  # the own cells' edge is behind the body there
        if (clear[sy[clear_of], sx[clear_of]] < body_m).any():
            continue
        return tx, ty
    return None
