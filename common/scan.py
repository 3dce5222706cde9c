"""A planar lidar's scan as points: what localization matches against the map and
navigation watches for people (`common.messages.sim.LaserScan`)."""

from __future__ import annotations

import numpy as np

from common.geometry import FloatArray


def scan_points(
    ranges: FloatArray,
    angle_min: float,
    angle_increment: float,
    T_base_lidar: FloatArray,
    stride: int = 1,
) -> FloatArray:
    """The scan's returns (0 = none) as (n, 2) points in the base's floor plane, in beam
    order (the lidar's mount applied; its tilt with the trunk is left out: under 4 mm per
    metre of range at the trot's 4-5° of roll and pitch)."""
    r = np.asarray(ranges, dtype=float)[::stride]
    a = angle_min + angle_increment * np.arange(0, len(ranges), stride)
    hit = r > 0.0
    r, a = r[hit], a[hit]
    p = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], axis=1)
    T = np.asarray(T_base_lidar, dtype=float).reshape(4, 4)
    out: FloatArray = (p @ T[:3, :3].T + T[:3, 3])[:, :2]
    return out
