"""RGB-D geometry of one segmented instance: frames, centroid, heading.

- Eq. 1 (`t_p = K⁻¹ [u v 1]ᵀ d` for every masked pixel with a depth return) is
  `common.camera.backproject`, shared with navigation and the map.
- The points go to `base` with the full `T_base_camera` (rotation included), then to
  `base_yaw` (the base's origin and heading, z up) and to the world with `T_world_base`.
- `robust_centroid`: the mean of the points depth-connected to the median depth (no gap
  wider than 3 cm + 2 % of the depth between neighbours in depth): mask pixels that bled
  onto the background behind, or onto an occluder in front, are rejected; an object's own
  points are dense in depth and are all kept (no trimming bias on clean data).
- d_obj and θ_obj (eq. 2) of a point in `base_yaw`. The object's axis and extent from
  its points are `fits`.

Pure numpy: values in, values out; `node.py` does the transport.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import numpy.typing as npt

from common.geometry import BoolArray, FloatArray, inv_T, yaw_only

Shape = Literal["cylinder", "box", "centroid"]

#: Which fit each class gets; unknown classes get the centroid alone.
CLASS_SHAPES: dict[str, Shape] = {"bottle": "cylinder", "can": "cylinder", "box": "box"}
MAD_TO_SIGMA = 1.4826
#: A depth gap wider than GAP_M + GAP_REL × depth separates an object from what its mask
#: bled onto (m, and a fraction of the depth: real sensors' noise grows with depth).
GAP_M = 0.03
GAP_REL = 0.02
#: Statistics and fits use at most this many points (an even stride through them): the
#: geometry of a near object is over-sampled and the budget is milliseconds.
MAX_FIT_POINTS = 1500


def T_base_yaw_base(T_world_base: npt.ArrayLike) -> FloatArray:
    """`base` in `base_yaw` (the roll and pitch of the trunk; no translation)."""
    T = np.asarray(T_world_base, dtype=float)
    return np.asarray(inv_T(yaw_only(T)) @ T)


def heading(p_base_yaw: npt.ArrayLike) -> tuple[float, float]:
    """Eq. 2: d_obj (horizontal distance, m) and θ_obj = atan2(y, x) (rad) in base_yaw."""
    x, y = float(np.asarray(p_base_yaw)[0]), float(np.asarray(p_base_yaw)[1])
    return math.hypot(x, y), math.atan2(y, x)


def thin(points: FloatArray, max_points: int = MAX_FIT_POINTS) -> FloatArray:
    """At most `max_points` of the points, at an even stride (deterministic)."""
    stride = -(-len(points) // max_points)
    return points[::stride] if stride > 1 else points


def robust_inliers(points: FloatArray, gap_m: float = GAP_M, gap_rel: float = GAP_REL) -> BoolArray:
    """The points depth-connected to the median depth (camera frame, z = depth).

    Sorted by depth, the points split wherever two neighbours are more than
    `gap_m + gap_rel × median depth` apart; the run holding the median is the object
    (mask pixels bled onto the background behind it, or onto an occluder in front, lie
    across such a gap). A surface's own points never split: their depths are dense.
    """
    return depth_inliers(points[:, 2], gap_m, gap_rel)


def depth_inliers(z: FloatArray, gap_m: float = GAP_M, gap_rel: float = GAP_REL) -> BoolArray:
    """`robust_inliers` of points given by their depths (N,) alone."""
    order = np.argsort(z, kind="stable")
    zs = z[order]
    mid = len(zs) // 2
    split = np.flatnonzero(np.diff(zs) > gap_m + gap_rel * zs[mid])
    i = int(np.searchsorted(split, mid))  # split[:i] below the median, split[i:] above
    lo = int(split[i - 1]) + 1 if i > 0 else 0
    hi = int(split[i]) + 1 if i < len(split) else len(zs)
    keep = np.zeros(len(z), dtype=bool)
    keep[order[lo:hi]] = True
    return keep


def robust_centroid(points: FloatArray) -> tuple[FloatArray, BoolArray]:
    """The mean of the `robust_inliers` and their mask."""
    if len(points) == 0:
        raise ValueError("no points: nothing to take the centroid of")
    keep = robust_inliers(points)
    return points[keep].mean(axis=0), keep
