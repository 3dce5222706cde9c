"""`dume trial goals [--world hall] [--world-seed N] [--count 10]`: random goals in a row.

Over the full navigation stack (`bench.nav_run.nav_stack`), lockstep, dynamic gait. The
goals are drawn (seeded by the world seed) from the world's truth occupancy: cells whose
clearance holds the footprint at any yaw with a margin, at least `min_hop_m` from the
previous goal, `person_margin_m` from every person, and reachable from the previous one
(navigation's own planner on the truth costmap, the robot's plan is its own); a random
yaw. They are walked one after the other; per goal and in total the truth figures of
`bench.nav_run`: reached, times, path length, final errors, closest approaches, contacts.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from bench.nav_run import NavRun, nav_stack
from common.config import REPO_ROOT, Overrides, PlannerSettings
from common.messages.world import WorldDescription
from services.navigation.costmap import CostParams, build_costmap
from services.navigation.grid import Footprint, Grid, Pose
from services.navigation.planner import PlanError, plan


def draw_goals(
    world: WorldDescription,
    start: tuple[float, float, float],
    count: int,
    seed: int,
    min_hop_m: float = 3.0,
    margin_m: float = 0.15,
    person_margin_m: float = 1.5,
) -> list[tuple[float, float, float]]:
    fp = Footprint.stowed()
    cm = build_costmap(Grid.from_world(world.occupancy), fp, CostParams())
    ok = cm.clearance >= fp.circumscribed + margin_m
    cells = np.argwhere(ok)
    xy = cm.grid.centres(cells)
    people = np.array([p.position for p in world.people]).reshape(-1, 2)
    if len(people):
        near = np.min(np.hypot(xy[:, None, 0] - people[:, 0], xy[:, None, 1] - people[:, 1]), 1)
        xy = xy[near >= person_margin_m + fp.circumscribed]
    rng = np.random.default_rng(seed)
    goals: list[tuple[float, float, float]] = []
    here = Pose(*start)
    for _ in range(100 * count):
        if len(goals) == count:
            break
        x, y = xy[rng.integers(len(xy))]
        if math.hypot(x - here.x, y - here.y) < min_hop_m:
            continue
        goal = Pose(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
        try:
            plan(cm, here, goal, fp, PlannerSettings())
        except PlanError:
            continue
        goals.append((round(goal.x, 3), round(goal.y, 3), round(goal.yaw, 3)))
        here = goal
    return goals


def goals_trial(
    count: int = 10, world: str = "hall", seed: int = 3, overrides: Overrides | None = None
) -> dict[str, Any]:
    wall0 = time.monotonic()
    per_goal: list[dict[str, Any]] = []
    with nav_stack(world, seed, overrides) as stack:
        run = NavRun(stack)
        goals = draw_goals(run.world, run.pose(), count, seed)
        for x, y, yaw in goals:
            per_goal.append(run.goto(x, y, yaw).as_json())
        estimates = run.estimates()
        logs = str(stack.run_dir.relative_to(REPO_ROOT))
    contacts: dict[str, int] = {}
    for g in per_goal:
        for k, v in g["contacts"].items():
            contacts[k] = contacts.get(k, 0) + v
    obstacle = [g["closest_obstacle_m"] for g in per_goal if g["closest_obstacle_m"] is not None]
    person = [g["closest_person_m"] for g in per_goal if g["closest_person_m"] is not None]
    return {
        "trial": "goals",
        "world": world,
        "world_seed": seed,
        "goals": len(goals),
        "reached": sum(g["reached"] for g in per_goal),
        "contacts": contacts,
        "closest_obstacle_m": min(obstacle, default=None),
        "closest_person_m": min(person, default=None),
        "sim_s": round(sum(g["sim_s"] or 0.0 for g in per_goal), 1),
        "path_m": round(sum(g["path_m"] or 0.0 for g in per_goal), 1),
        "wall_s": round(time.monotonic() - wall0, 1),
        "logs": logs,
        **estimates,
        "per_goal": per_goal,
    }
