"""Where the dataset's cameras stand: free floor points, views of an artifact from afar,
views of furniture edges, and the held-out plan of the segmenter's confusion report.

The training plan itself is `services.sim.dataset.plan_shots`; what it adds to its first
kinds of frames comes from here, drawn from a generator of its own so that the frames
drawn before stay the same:
- `far_shots`: artifacts from 1.5-3 m (`FAR_RING_M`, the base's distance), the wrist
  camera held up in `look` as the mapping patrol holds it, or the head camera; artifacts
  on benches drawn twice as often, cans and boxes 1.5 times as often as bottles (the
  patrol's misses: cans on benches read as boxes from 2-3 m, or not at all; on held-out
  renders from there the shipped network read 35 % of cans and 36 % of boxes right, 68 %
  of bottles);
- `edge_shots`: a point on an edge of a table, bench or pallet (`EDGE_KINDS`) with no
  artifact within `EDGE_CLEAR_M`, seen from 0.8-3 m: negatives, where the network put
  boxes (on a pallet, on a table's edge).

`plan_heldout_shots` is the confusion report's: each artifact from near, middle and far
(about 0.5-1.5, 1.5-3 and 3-5 m from the camera), both cameras, each person from 1-5 m,
and furniture edges; used on seeds no model trains on.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common import robot
from common.messages.world import Artifact, Obstacle, WorldDescription
from services.sim import feasibility as fz

#: Frames per seed of artifacts from afar and of furniture edges (training).
FAR_FRAMES = 6
EDGE_FRAMES = 4
#: The base's distance from the artifact in `far_shots` (m); the camera stands a few
#: decimetres ahead of the base, so it is about 1.3-2.9 m from it.
FAR_RING_M = (1.6, 3.2)
#: Furniture whose edges are the negatives, and how far from any artifact (m).
EDGE_KINDS = ("table", "bench", "pallet")
EDGE_CLEAR_M = 0.8
EDGE_RING_M = (0.8, 3.0)
#: The held-out plan: the base's distance from each artifact per view (m), near, middle
#: and far (besides the wrist's standoff, `robot.D_OPT_M` and a little beyond), and from
#: people.
HELDOUT_RINGS_M = ((0.9, 1.6), (1.6, 3.2), (3.2, 5.2))
HELDOUT_PERSON_RING_M = (1.0, 5.0)
HELDOUT_EDGE_FRAMES = 6


class Shot(NamedTuple):
    """Where to put the robot and which camera to capture."""

    camera: str
    x: float
    y: float
    yaw: float
    posture: str


class Floor:
    """Free points of a world's floor, drawn with a generator."""

    def __init__(self, world: WorldDescription, rng: np.random.Generator) -> None:
        self.grid, self.rng = world.occupancy, rng
        self.clear = fz.clearance(world.occupancy)

    def point(
        self,
        clearance_m: float,
        near: tuple[float, float] | None = None,
        ring: tuple[float, float] = (0.0, math.inf),
    ) -> tuple[float, float]:
        """A free point with `clearance_m`, within `ring` of `near` when one fits."""
        res, (x0, y0) = self.grid.resolution, self.grid.origin
        mask = self.clear >= clearance_m
        if near is not None:
            ny, nx = mask.shape
            xs = x0 + (np.arange(nx) + 0.5) * res - near[0]
            ys = y0 + (np.arange(ny) + 0.5) * res - near[1]
            dist = np.hypot(xs[None, :], ys[:, None])
            in_ring = mask & (dist >= ring[0]) & (dist <= ring[1])
            mask = in_ring if in_ring.any() else mask
        idx = np.flatnonzero(mask)
        iy, ix = np.unravel_index(int(idx[self.rng.integers(idx.size)]), mask.shape)
        return float(x0 + (ix + self.rng.random()) * res), float(
            y0 + (iy + self.rng.random()) * res
        )


def facing(x: float, y: float, target: tuple[float, float], rng: np.random.Generator) -> float:
    """The yaw from (x, y) towards `target`, jittered ±0.35 rad."""
    return math.atan2(target[1] - y, target[0] - x) + float(rng.uniform(-0.35, 0.35))


def _camera(rng: np.random.Generator, wrist_share: float) -> tuple[str, str]:
    """(camera, posture): the wrist held up in `look` at `wrist_share`, else the head
    camera with the arm in any of its carrying postures."""
    if rng.random() < wrist_share:
        return "camera_wrist", "look"
    return "camera_head", ("stand", "stow", "look")[int(rng.integers(3))]


def view(
    floor: Floor,
    rng: np.random.Generator,
    target: tuple[float, float],
    ring: tuple[float, float],
    wrist_share: float,
) -> Shot:
    """A camera facing `target` from a free point `ring` away from it."""
    x, y = floor.point(0.5, target, ring)
    camera, posture = _camera(rng, wrist_share)
    return Shot(camera, x, y, facing(x, y, target, rng), posture)


def far_shots(world: WorldDescription, rng: np.random.Generator, count: int) -> list[Shot]:
    """`count` views of artifacts from `FAR_RING_M`, two in three with the wrist camera,
    artifacts on benches drawn twice as often as those on tables, cans and boxes 1.5
    times as often as bottles."""
    if not world.artifacts:
        return []
    weight = np.array(
        [
            (2.0 if a.surface_id.startswith("bench") else 1.0)
            * (1.0 if a.object_class == "bottle" else 1.5)
            for a in world.artifacts
        ]
    )
    picks = rng.choice(len(world.artifacts), size=count, p=weight / weight.sum())
    floor = Floor(world, rng)
    return [
        view(floor, rng, _xy(world.artifacts[int(k)]), FAR_RING_M, 2 / 3) for k in picks.tolist()
    ]


def edge_point(
    world: WorldDescription, rng: np.random.Generator, tries: int = 20
) -> tuple[float, float] | None:
    """A point on an edge of one of the world's `EDGE_KINDS` with no artifact within
    `EDGE_CLEAR_M` (None when no try finds one)."""
    furniture = [o for o in world.obstacles if o.kind in EDGE_KINDS]
    if not furniture:
        return None
    for _ in range(tries):
        point = _on_edge(furniture[int(rng.integers(len(furniture)))], rng)
        if all(math.dist(point, _xy(a)) >= EDGE_CLEAR_M for a in world.artifacts):
            return point
    return None


def _on_edge(o: Obstacle, rng: np.random.Generator) -> tuple[float, float]:
    hx, hy = o.half_size[0], o.half_size[1]
    along = float(rng.uniform(-1.0, 1.0))
    side = 1.0 if rng.random() < 0.5 else -1.0
    u, v = (along * hx, side * hy) if rng.random() < 0.5 else (side * hx, along * hy)
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    return o.centre[0] + c * u - s * v, o.centre[1] + s * u + c * v


def edge_shots(world: WorldDescription, rng: np.random.Generator, count: int) -> list[Shot]:
    """Up to `count` views of furniture edges with no artifact near (`edge_point`), from
    `EDGE_RING_M`, half with the wrist camera."""
    floor = Floor(world, rng)
    shots = []
    for _ in range(count):
        point = edge_point(world, rng)
        if point is not None:
            shots.append(view(floor, rng, point, EDGE_RING_M, 0.5))
    return shots


def plan_heldout_shots(world: WorldDescription, rng: np.random.Generator) -> list[Shot]:
    """The confusion report's views (see the module docstring): per artifact, the wrist
    camera at its standoff in `look`, and from each of `HELDOUT_RINGS_M` the wrist camera
    in `look` and the head camera; per person, the head and the wrist camera from
    `HELDOUT_PERSON_RING_M`; `HELDOUT_EDGE_FRAMES` furniture edges."""
    surfaces = {s.id: s for s in world.surfaces}
    floor = Floor(world, rng)
    shots: list[Shot] = []
    for a in world.artifacts:
        distance = float(rng.uniform(robot.D_OPT_M, robot.STANDOFF_DISTANCE_M + 0.3))
        heading = robot.THETA_OPT_RAD + float(rng.uniform(-0.3, 0.3))
        pose = fz.standoff_pose_for(a, surfaces[a.surface_id], distance, heading)
        shots.append(Shot("camera_wrist", pose.x, pose.y, pose.yaw, "look"))
        for ring in HELDOUT_RINGS_M:
            shots.append(view(floor, rng, _xy(a), ring, 1.0))
            shots.append(view(floor, rng, _xy(a), ring, 0.0))
    for person in world.people:
        shots.append(view(floor, rng, person.position, HELDOUT_PERSON_RING_M, 0.0))
        shots.append(view(floor, rng, person.position, HELDOUT_PERSON_RING_M, 1.0))
    return shots + edge_shots(world, rng, HELDOUT_EDGE_FRAMES)


def _xy(a: Artifact) -> tuple[float, float]:
    return a.position[0], a.position[1]
