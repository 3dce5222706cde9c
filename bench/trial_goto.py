"""`dume trial goto X Y [--yaw Θ] [--world hall|small] [--world-seed N]`: walk to a pose.

Over the full navigation stack (`bench.nav_run.nav_stack`: sim, WBC with its dynamic
gait, the semantic map seeded from the world, navigation on the map's queryables),
lockstep. One `PoseGoal` (tolerances 0.1 m, 0.1 rad); the figures are the truth's:
reached, sim and wall time, path length walked, final position and yaw error, closest
approach of the footprint to static obstacles and to people, contacts.
"""

from __future__ import annotations

import time
from typing import Any

from bench.nav_run import NavRun, nav_stack
from common.config import REPO_ROOT, Overrides


def goto(
    x: float,
    y: float,
    yaw: float = 0.0,
    world: str = "hall",
    seed: int = 3,
    overrides: Overrides | None = None,
) -> dict[str, Any]:
    wall0 = time.monotonic()
    with nav_stack(world, seed, overrides) as stack:
        run = NavRun(stack)
        start = run.pose()
        g = run.goto(x, y, yaw)
        logs = str(stack.run_dir.relative_to(REPO_ROOT))
    return {
        "trial": "goto",
        "world": world,
        "world_seed": seed,
        "start": [round(v, 3) for v in start],
        **g.as_json(),
        "total_wall_s": round(time.monotonic() - wall0, 1),
        "logs": logs,
    }
