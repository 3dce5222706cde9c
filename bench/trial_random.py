"""The `random` trial: random velocity commands for 120 s of sim time inside free space.

A new (vx, vy, ωz) uniform within the limits every 2 s; the robot must never fall. It
stays inside a disc of free floor: the truth world description (`dume/world/description`:
obstacles and people; truth, as every trial's set-up) gives the point near the start
farthest from everything that the robot can walk to in a straight line (`free_disc`),
and the disc's radius leaves the robot's own size and its stopping distance to the
nearest obstacle. Every driver tick (20 ms) the robot is checked: once out of the disc,
the random command is dropped and it walks back towards the centre at 0.5 m/s until it
is halfway in, then a new random command starts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.trial_driver import Driver, Script
from common.geometry import FloatArray
from common.keys import WORLD_DESCRIPTION
from common.messages.world import Obstacle, WorldDescription

Figures = dict[str, Any]
ROBOT_RADIUS_M = 0.75  # the base's centre to the farthest point of the robot, with margin
STOP_M = 0.4  # from 0.8 m/s at the gait's 1 m/s² deceleration, with margin
PERSON_RADIUS_M = 0.35
MAX_RADIUS_M = 2.5
SEGMENT_S = 2.0
RETURN_SPEED = 0.5
LIMITS = np.array([0.8, 0.4, 1.0])  # the commanded range: the WBC's cmd_vel limits


def box_distance(box: Obstacle, p: FloatArray) -> float:
    """Distance (m) from the floor point p (2,) to the box's footprint (0 inside)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    dx, dy = p[0] - box.centre[0], p[1] - box.centre[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    ex = max(abs(lx) - box.half_size[0], 0.0)
    ey = max(abs(ly) - box.half_size[1], 0.0)
    return math.hypot(ex, ey)


def clearance(world: WorldDescription, p: FloatArray) -> float:
    """Distance (m) from p (2,) to the nearest obstacle footprint or person."""
    d = min((box_distance(o, p) for o in world.obstacles), default=math.inf)
    for person in world.people:
        px, py = person.position[0], person.position[1]
        d = min(d, math.hypot(p[0] - px, p[1] - py) - PERSON_RADIUS_M)
    return d


def free_disc(
    world: WorldDescription, start: FloatArray, search_m: float = 4.0, step_m: float = 0.25
) -> tuple[FloatArray, float]:
    """The centre (2,) and clearance (m) of the freest floor point within `search_m` of
    `start` that the robot reaches in a straight line (keeping ROBOT_RADIUS_M all the
    way); a little nearer is preferred at equal room."""
    ticks = np.arange(-search_m, search_m + 1e-9, step_m)
    candidates = []
    for x in ticks:
        for y in ticks:
            p = np.array([start[0] + x, start[1] + y])
            far = math.hypot(x, y)
            if far <= search_m:
                room = min(clearance(world, p), MAX_RADIUS_M + ROBOT_RADIUS_M + STOP_M)
                candidates.append((room - 0.1 * far, room, p))
    candidates.sort(key=lambda c: -c[0])
    for _, room, p in candidates:
        n = max(2, int(np.linalg.norm(p - start) / 0.1))
        path = (start + (p - start) * k / n for k in range(n + 1))
        if all(clearance(world, q) >= ROBOT_RADIUS_M for q in path):
            return p, room
    return np.asarray(start, float), clearance(world, start)


def random_walk(d: Driver, out: Figures, seconds: float = 120.0, seed: int = 0) -> Script:
    """Random (vx, vy, ωz) within the limits every 2 s, inside the free disc."""
    rng = np.random.default_rng(seed)
    world = d.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
    start, _ = d.base()
    centre, room = free_disc(world, start)
    radius = max(min(room - ROBOT_RADIUS_M - STOP_M, MAX_RADIUS_M), 0.3)
    d.mode("walk")
    yield from d.wait(0.5)
    end, next_segment = d.t + seconds, d.t
    segments = returns = 0
    returning, excursion, entered = False, 0.0, False
    while d.t < end:
        p, yaw = d.base()
        e = centre - p
        dist = float(np.linalg.norm(e))
        entered = entered or dist < radius  # the walk from the start to the disc aside
        excursion = max(excursion, dist if entered else 0.0)
        if not returning and dist > radius:
            returning, returns = True, returns + 1
        if returning and dist < 0.5 * radius:
            returning, next_segment = False, d.t
        if returning:
            c, s = math.cos(yaw), math.sin(yaw)
            back = RETURN_SPEED * np.array([c * e[0] + s * e[1], -s * e[0] + c * e[1]]) / dist
            d.cmd(float(back[0]), float(back[1]), 0.0)
        elif d.t >= next_segment:
            d.cmd(*(float(x) for x in rng.uniform(-1.0, 1.0, 3) * LIMITS))
            segments, next_segment = segments + 1, d.t + SEGMENT_S
        yield
    d.cmd(0.0)
    yield from d.wait(2.0)
    out |= {
        "random_segments": segments,
        "return_segments": returns,
        "free_centre": [round(float(x), 2) for x in centre],
        "free_clearance_m": round(room, 2),
        "radius_m": round(radius, 2),
        "max_excursion_m": round(excursion, 2),
    }
