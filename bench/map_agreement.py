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
"""

from __future__ import annotations

from typing import Any

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
