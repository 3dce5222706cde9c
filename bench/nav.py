"""`dume bench nav`: global planning time on a 40 × 40 m grid at 5 cm (800 × 800 cells).

A warehouse-like floor (seeded: perimeter walls, rows of racks with cross aisles, some
machines), inflated by the robot's footprint (`services.navigation.costmap`); random
start/goal pairs at least 15 m apart in free space. For each pair: the full `plan`
(goal check, A*, smoothing, poses), and A* and a plain Dijkstra (the same search with
the heuristic off) on the same cost grid in the same run; their costs must agree.
Figures: p50/p99 in ms (wall; and the plan's CPU time, which a loaded machine does not
inflate), nodes expanded, whether the compiled search is in use.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from common.config import Overrides, PlannerSettings
from services.navigation import native
from services.navigation.costmap import CostParams, build_costmap
from services.navigation.grid import Footprint, Grid, Pose
from services.navigation.planner import plan

SIZE_M, RES = 40.0, 0.05


def warehouse(seed: int = 0) -> Grid:
    n = round(SIZE_M / RES)
    rng = np.random.default_rng(seed)
    occ = np.zeros((n, n), dtype=bool)
    occ[:4, :] = occ[-4:, :] = occ[:, :4] = occ[:, -4:] = True
    for row in range(60, n - 60, 90):  # rack rows 1 m deep, 3.5 m aisles, cross aisles
        for col in range(40, n - 120, 160):
            if rng.random() < 0.85:
                occ[row : row + 20, col : col + 120] = True
    for _ in range(12):  # machines
        y, x = rng.integers(20, n - 60, 2)
        occ[y : y + rng.integers(20, 40), x : x + rng.integers(20, 40)] = True
    return Grid(occ, RES, (0.0, 0.0))


def bench_nav(overrides: Overrides | None = None, pairs: int = 30, seed: int = 0) -> dict[str, Any]:
    del overrides
    fp = Footprint.stowed()
    grid = warehouse(seed)
    t0 = time.perf_counter()
    cm = build_costmap(grid, fp, CostParams())
    costmap_ms = (time.perf_counter() - t0) * 1e3
    rng = np.random.default_rng(seed + 1)
    free = np.argwhere(cm.cost == 0)
    params = PlannerSettings()
    native.search(cm.cost, tuple(free[0]), tuple(free[1]), params.cost_weight)  # build/load
    plan_ms: list[float] = []
    plan_cpu_ms: list[float] = []
    astar_ms: list[float] = []
    dijkstra_ms: list[float] = []
    expanded: list[tuple[int, int]] = []
    mismatches = 0
    while len(plan_ms) < pairs:
        a, b = free[rng.integers(len(free), size=2)]
        if math.dist(a, b) * RES < 15.0:
            continue
        s, g = grid.centre(*a), grid.centre(*b)
        t, c = time.perf_counter(), time.process_time()
        plan(cm, Pose(s[0], s[1], 0.0), Pose(g[0], g[1], 0.0), fp, params)
        plan_ms.append((time.perf_counter() - t) * 1e3)
        plan_cpu_ms.append((time.process_time() - c) * 1e3)
        t = time.perf_counter()
        fa = native.search(cm.cost, tuple(a), tuple(b), params.cost_weight)
        astar_ms.append((time.perf_counter() - t) * 1e3)
        t = time.perf_counter()
        fd = native.search(cm.cost, tuple(a), tuple(b), params.cost_weight, heuristic=False)
        dijkstra_ms.append((time.perf_counter() - t) * 1e3)
        expanded.append((fa.expanded, fd.expanded))
        mismatches += int(not math.isclose(fa.cost, fd.cost, rel_tol=1e-9))

    def pct(x: list[float], q: float) -> float:
        return round(float(np.percentile(x, q)), 2)

    return {
        "grid": f"{grid.shape[1]}x{grid.shape[0]} cells at {RES} m",
        "pairs": pairs,
        "compiled_search": native.compiled(),
        "costmap_ms": round(costmap_ms, 1),
        "plan_p50_ms": pct(plan_ms, 50),
        "plan_p99_ms": pct(plan_ms, 99),
        "plan_cpu_p50_ms": pct(plan_cpu_ms, 50),
        "plan_cpu_p99_ms": pct(plan_cpu_ms, 99),
        "astar_p50_ms": pct(astar_ms, 50),
        "astar_p99_ms": pct(astar_ms, 99),
        "dijkstra_p50_ms": pct(dijkstra_ms, 50),
        "dijkstra_p99_ms": pct(dijkstra_ms, 99),
        "astar_expanded_p50": int(np.median([e[0] for e in expanded])),
        "dijkstra_expanded_p50": int(np.median([e[1] for e in expanded])),
        "cost_mismatches": mismatches,
    }
