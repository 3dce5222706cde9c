"""`dume bench slam`: the SLAM (`services.localization.slam`) round a synthetic hall from
nothing, on ray-cast scans (±1.5 cm) and odometry that drifts (3 % long, 0.8° per metre
to the left), once per loop-closure registration (`localization.slam.closure_registration`:
`field`, the correlative search and Gauss-Newton refine on the submap's grid, and `gicp`,
small_gicp's GICP on the submap's returns): the pose error against the truth (p50, p95,
max, and over the last 4 m, after the loop closed), the closures taken, the keyframes
and how many the closures cast into the grid again, the registration's wall ms per
closure and the wall ms per scan. The same hall and loop are the unit tests'
(`tests/unit/test_slam.py`).
"""

from __future__ import annotations

import itertools
import math
import time
from typing import Any

import numpy as np

from bench.raycast import ANGLES, T_BASE_LIDAR, Box, overlap_grid, slab_ranges
from common.config import LocalizationSettings, Overrides, load_config
from common.scan import scan_points
from services.localization.localizer import compose, inverse
from services.localization.slam import ScanGrid, Slam

HALL: list[Box] = [
    (-7.0, -5.1, 7.0, -5.0),  # walls of a 14 × 10 m hall
    (-7.0, 5.0, 7.0, 5.1),
    (-7.1, -5.1, -7.0, 5.1),
    (7.0, -5.1, 7.1, 5.1),
    (-3.0, 1.0, -1.0, 2.2),  # a machine, pallets, a pillar, a bench
    (2.0, -2.5, 3.2, -1.5),
    (4.5, 2.0, 5.7, 2.8),
    (-0.2, -0.2, 0.2, 0.2),
    (-5.5, -3.8, -3.9, -3.2),
]


def cast(pose: tuple[float, float, float], rng: np.random.Generator) -> np.ndarray:
    """The lidar's ranges against the hall's boxes, ±1.5 cm noise, 0 beyond 10 m."""
    return slab_ranges(HALL, pose, 0.015, rng)


def points(ranges: np.ndarray) -> np.ndarray:
    return scan_points(ranges, float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), T_BASE_LIDAR)


def loop_path(step_m: float = 0.1) -> list[tuple[float, float, float]]:
    """Round the hall's middle, 1.5–2 m from the walls, and back past the start."""
    corners = [(-5.0, -2.0), (5.5, -3.5), (5.5, 3.8), (-5.5, 3.8), (-5.0, -2.0), (0.0, -3.0)]
    path: list[tuple[float, float, float]] = []
    for (x0, y0), (x1, y1) in itertools.pairwise(corners):
        yaw = math.atan2(y1 - y0, x1 - x0)
        n = int(math.hypot(x1 - x0, y1 - y0) / step_m)
        path += [(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
    return path


def drifting_odometry(path: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    """The path as odometry that overestimates distance by 3 % and turns 0.8° per metre
    too far left: 0.5 m and 25° off after the loop."""
    odom = [(0.0, 0.0, 0.0)]
    for a, b in itertools.pairwise(path):
        rel = compose(inverse(a), b)
        d = math.hypot(rel[0], rel[1])
        rel = (rel[0] * 1.03, rel[1] * 1.03, rel[2] + math.radians(0.8) * d)
        odom.append(compose(odom[-1], rel))
    return odom


def hall_occupancy(grid: ScanGrid) -> np.ndarray:
    """The boxes rasterised on the SLAM grid (a cell is occupied when a box overlaps it)."""
    return overlap_grid(HALL, grid.origin_xy, grid.shape, grid.resolution_m)


def run_loop(s: LocalizationSettings | None = None) -> tuple[Slam, list[float]]:
    """The loop, scan by scan; the SLAM after it and its position error per scan, m."""
    s = s or LocalizationSettings()
    path = loop_path()
    odom = drifting_odometry(path)
    rng = np.random.default_rng(3)
    slam = Slam(s, s.slam, path[0], (float(T_BASE_LIDAR[0, 3]), float(T_BASE_LIDAR[1, 3])))
    errors = []
    for true, od in zip(path, odom, strict=True):
        est = slam.update(points(cast(true, rng)), od, stride=s.beam_stride)
        errors.append(math.hypot(est.map_base[0] - true[0], est.map_base[1] - true[1]))
    return slam, errors


def _percentiles(values: list[float], scale: float = 1.0, digits: int = 4) -> dict[str, float]:
    a = np.asarray(values) * scale
    return {
        "p50": round(float(np.percentile(a, 50)), digits),
        "p95": round(float(np.percentile(a, 95)), digits),
        "max": round(float(a.max()), digits),
    }


def bench_slam(settings: Overrides) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for how in ("field", "gicp"):
        s = load_config({**settings, "localization.slam.closure_registration": how}).localization
        t0 = time.perf_counter()
        slam, errors = run_loop(s)
        wall = time.perf_counter() - t0
        out[how] = {
            "position_error_m": _percentiles(errors),
            "after_closure_max_m": round(max(errors[-40:]), 4),
            "closures": len(slam.closures),
            "keyframes": len(slam.keyframes),
            "keyframes_cast_again": slam.recast,
            "closure_ms": _percentiles(slam.closure_ms, digits=1) if slam.closure_ms else {},
            "ms_per_scan": round(1e3 * wall / len(errors), 2),
        }
    return out
