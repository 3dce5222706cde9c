"""How well a map the robot built agrees with the world's floor plan (truth; evaluation only).

`truth_on(world, shape, res, origin, z=None)` rasterises the world's obstacles (oriented
boxes standing on the floor) on a map's grid as the sim rasterises its own 5 cm grid
(`feasibility.rect_mask`): a cell is occupied when its centre lies in a box grown by half
a cell (a box overlapping the cell); with `z`, only the boxes whose height spans z (what
a planar lidar at that height can see).

`agreement(cells, truth)`: over the cells the map knows (not unknown), the IoU of the
occupied cells within one cell (5 cm): a map cell counts as agreeing when a truth cell
lies within one cell of it, and a truth cell the map could see (one beside floor the map
knows is free: a wall's face, not its inside) when a map cell lies within one of it;
IoU = agreeing / (map's occupied + truth's seen occupied). Also the share of the
truth's free floor the map knows as free, and how much it knows at all.

`align_to_truth(cells, truth, res, origin)`: the rigid motion (a turn about the map's
obstacles' centre, then a shift) that best lays the map's obstacle cells on the truth's
(the mean distance to the nearest truth cell, clipped at 0.3 m, least over a grid of
turns within 2° and shifts within 0.3 m; then, of that motion snapped to whole cells,
its neighbours and no motion at all, the one whose grid agrees best by the IoU above).
A map the robot made from nothing is in its own frame, anchored at the start pose it was
told: a heading off by half a degree there turns the whole hall, 8 cm at 10 m, while its
walls agree with each other to a cell.
The report gives the IoU both as the map lies and after this alignment, and the
alignment itself (how far the map's frame is from the world's), as SLAM maps are judged
up to a rigid motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from common.messages.world import WorldDescription
from services.sim.feasibility import rect_mask

FREE, OCCUPIED, UNKNOWN = 0, 100, 255


def truth_on(
    world: WorldDescription,
    shape: tuple[int, int],
    resolution_m: float,
    origin_xy: tuple[float, float],
    z: float | None = None,
) -> NDArray[np.bool_]:
    xs = origin_xy[0] + (np.arange(shape[1], dtype=np.float64) + 0.5) * resolution_m
    ys = origin_xy[1] + (np.arange(shape[0], dtype=np.float64) + 0.5) * resolution_m
    occ = np.zeros(shape, bool)
    h = 0.5 * resolution_m
    for ob in world.obstacles:
        cz, hz = ob.centre[2], ob.half_size[2]
        if z is not None and not (cz - hz <= z <= cz + hz):
            continue
        hx, hy = ob.half_size[0] + h, ob.half_size[1] + h
        occ |= rect_mask(xs, ys, ob.centre[:2], ob.yaw, (-hx, hx), (-hy, hy))
    return occ


def agreement(
    cells: NDArray[np.uint8], truth: NDArray[np.bool_], resolution_m: float = 0.05
) -> dict[str, Any]:
    seen = cells != UNKNOWN
    mine = cells == OCCUPIED
    near_truth = ndimage.binary_dilation(truth, iterations=1)
    near_mine = ndimage.binary_dilation(mine, iterations=1)
    # the truth the map could have seen: obstacle cells beside floor it knows is free (a
    # wall's inside is never seen, nor the far side of a pillar)
    seen_truth = truth & ndimage.binary_dilation(cells == FREE, iterations=1)
    agree = int((mine & near_truth).sum() + (seen_truth & near_mine).sum())
    total = int(mine.sum() + seen_truth.sum())
    floor = ~ndimage.binary_dilation(truth, iterations=2)
    return {
        "iou_within_5cm": round(agree / total, 3) if total else None,
        "occupied_cells": int(mine.sum()),
        "false_occupied_cells": int((mine & ~near_truth).sum()),
        "truth_seen_missed_cells": int((seen_truth & ~near_mine).sum()),
        "known_m2": round(float(seen.sum()) * resolution_m**2, 1),
        "free_known_share_of_seen_floor": round(
            float(((cells == FREE) & floor).sum()) / max(1, int((seen & floor).sum())), 3
        ),
    }


@dataclass(frozen=True)
class Alignment:
    """A turn by `yaw_rad` about `centre_xy`, then a shift by `shift_xy` (m, world)."""

    yaw_rad: float = 0.0
    shift_xy: tuple[float, float] = (0.0, 0.0)
    centre_xy: tuple[float, float] = (0.0, 0.0)

    def apply(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points (N, 2) moved by the alignment."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        d = np.atleast_2d(xy) - self.centre_xy
        return np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]]) + np.add(
            self.centre_xy, self.shift_xy
        )

    def warp(
        self, cells: NDArray[np.uint8], resolution_m: float, origin_xy: tuple[float, float]
    ) -> NDArray[np.uint8]:
        """The grid moved by the alignment (nearest cell; unknown where nothing lands)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        # cell (u, v) has its centre at origin + (u + 0.5, v + 0.5) res: in cells, the turn
        # is about the centre's cell and the shift is shift / res
        pc = (np.asarray(self.centre_xy) - origin_xy) / resolution_m - 0.5
        t = pc + np.asarray(self.shift_xy) / resolution_m - np.array([[c, -s], [s, c]]) @ pc
        m = np.array([[c, -s, t[0]], [s, c, t[1]]], np.float64)
        h, w = cells.shape
        return cv2.warpAffine(
            cells, m, (w, h), flags=cv2.INTER_NEAREST, borderValue=int(UNKNOWN)
        ).astype(np.uint8)


def align_to_truth(
    cells: NDArray[np.uint8],
    truth: NDArray[np.bool_],
    resolution_m: float,
    origin_xy: tuple[float, float],
    max_yaw_deg: float = 2.0,
    max_shift_m: float = 0.3,
) -> Alignment:
    """The best rigid alignment of the map's obstacle cells to the truth's (module
    docstring): a coarse grid of turns (0.1°) and shifts (2.5 cm), then a finer one."""
    iy, ix = np.nonzero(cells == OCCUPIED)
    if len(ix) == 0 or not truth.any():
        return Alignment()
    xy = np.column_stack(
        [origin_xy[0] + (ix + 0.5) * resolution_m, origin_xy[1] + (iy + 0.5) * resolution_m]
    )
    centre = (float(xy[:, 0].mean()), float(xy[:, 1].mean()))
    far = np.minimum(ndimage.distance_transform_edt(~truth) * resolution_m, 0.3)
    h, w = truth.shape

    def cost(a: Alignment) -> float:
        p = a.apply(xy)
        jx = np.floor((p[:, 0] - origin_xy[0]) / resolution_m).astype(np.intp)
        jy = np.floor((p[:, 1] - origin_xy[1]) / resolution_m).astype(np.intp)
        inside = (jx >= 0) & (jx < w) & (jy >= 0) & (jy < h)
        return float(np.where(inside, far[jy.clip(0, h - 1), jx.clip(0, w - 1)], 0.3).mean())

    best, best_cost = Alignment(centre_xy=centre), float("inf")
    for yaw_step, shift_step, yaw_span, shift_span in (
        (0.1, 0.025, max_yaw_deg, max_shift_m),
        (0.02, 0.005, 0.1, 0.025),
    ):
        y0, (sx0, sy0) = np.degrees(best.yaw_rad), best.shift_xy
        for yaw in np.arange(y0 - yaw_span, y0 + yaw_span + 1e-9, yaw_step):
            for dx in np.arange(sx0 - shift_span, sx0 + shift_span + 1e-9, shift_step):
                for dy in np.arange(sy0 - shift_span, sy0 + shift_span + 1e-9, shift_step):
                    a = Alignment(float(np.radians(yaw)), (float(dx), float(dy)), centre)
                    c = cost(a)
                    if c < best_cost:
                        best, best_cost = a, c
    return _best_agreeing(cells, truth, resolution_m, origin_xy, best)


def _best_agreeing(
    cells: NDArray[np.uint8],
    truth: NDArray[np.bool_],
    resolution_m: float,
    origin_xy: tuple[float, float],
    found: Alignment,
) -> Alignment:
    """Of the alignment the search found, the same snapped to whole cells and a cell
    either way, turned 0.05° either way, and no motion at all: the one whose warped grid
    agrees best (`agreement`'s IoU, the figure reported). The search's cost rounds each
    point to its cell, where a shift of half a cell lands points either side of a cell's
    edge; the warp moves the grid by whole cells. Judged by the figure itself, a map
    "aligned" never agrees less than as it lies (hall seed 2 read 0.754, aligned 0.618)."""

    def iou(a: Alignment) -> float:
        score = agreement(a.warp(cells, resolution_m, origin_xy), truth, resolution_m)
        return float(score["iou_within_5cm"] or 0.0)

    best, best_iou = Alignment(centre_xy=found.centre_xy), iou(Alignment())
    if (score := iou(found)) > best_iou:
        best, best_iou = found, score
    sx, sy = (round(v / resolution_m) for v in found.shift_xy)
    for dyaw in (-0.05, 0.0, 0.05):
        for i in (sx - 1, sx, sx + 1):
            for j in (sy - 1, sy, sy + 1):
                a = Alignment(
                    found.yaw_rad + float(np.radians(dyaw)),
                    (i * resolution_m, j * resolution_m),
                    found.centre_xy,
                )
                if (score := iou(a)) > best_iou:
                    best, best_iou = a, score
    return best
