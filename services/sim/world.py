"""Seeded worlds: `generate_world(seed, name)` gives the same `WorldDescription` per seed.

One `numpy.random.default_rng(seed)` drives everything, in a fixed order: the furniture
layout (`services.sim.layout`), its occupancy grid, the robot's start, the artifacts on the
front edges of tables and benches, the people, the lights (`services.sim.appearance`).
Artifacts are placed so that their standoff and pick poses (`services.sim.feasibility`) are
free and connected to the start, which bounds their depth from the edge by D_OPT minus the
footprint's front; people stand at least a metre from obstacles, clear of the goal poses,
turned so that their handover pose is free and connected too. A sample that cannot place
everything, or fails `check_paths`, is dropped and the next is drawn from the same
generator, so the result stays deterministic. The wrist camera sees every artifact from the
same relative pose (straight ahead, `STANDOFF_DISTANCE_M` away, `look` posture) and
neighbours stand `ARTIFACT_SPACING_M` apart, so visibility follows from the placement
rules; rendering verifies it in `services.sim.visibility.check_world` (not here: pixel
counts may differ between renderers, and a seed must give the same world everywhere).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence

import msgspec
import numpy as np

from common import robot
from common.messages import as_numpy
from common.messages.world import (
    Artifact,
    ArtifactClass,
    Cuboid,
    Cylinder,
    Hall,
    Obstacle,
    Person,
    Rgba,
    RobotStart,
    SupportSurface,
    WorldDescription,
)
from services.sim import feasibility as fz
from services.sim.appearance import (
    SHIRT_COLOURS,
    SKIN_COLOURS,
    TROUSERS_COLOURS,
    artifact_body,
    colour,
    lighting,
    uniform,
)
from services.sim.layout import Layout, hall_layout, small_layout

log = logging.getLogger(__name__)

WORLD_NAMES = ("hall", "small")
#: Samples drawn before giving up on a seed.
MAX_ATTEMPTS = 40
#: Artifacts on one surface keep at least this far apart, m.
ARTIFACT_SPACING_M = 0.3
#: Depth of an artifact's centre from its surface's front edge, m.
EDGE_DEPTH_M = (0.05, 0.20)
#: People stand at least this far (m) from obstacles (plus their own radius).
PERSON_CLEARANCE_M = 1.0
PERSON_RADIUS_M = 0.25
#: People keep this far (m) from the robot's start, its goal poses and each other.
PERSON_SPACING_M = 1.5
MAX_WALKING_SPEED_MPS = 1.2
#: The random stream people's routes are drawn from, apart from the world's own.
WALK_STREAM = 0x5A1C


class WorldGenerationError(RuntimeError):
    """No feasible world came out of `MAX_ATTEMPTS` samples; carries the last problems."""

    def __init__(self, name: str, seed: int, problems: Sequence[str]) -> None:
        super().__init__(f"no feasible {name!r} world for seed {seed}; last problems: {problems}")
        self.problems = list(problems)


def _footprint_radius(shape: Cylinder | Cuboid) -> float:
    if isinstance(shape, Cylinder):
        return shape.radius
    return math.hypot(shape.half_size[0], shape.half_size[1])


class _Sampler:
    """One attempt at a world: the layout and grid, then everything placed on them."""

    def __init__(self, rng: np.random.Generator, layout: Layout) -> None:
        self.rng = rng
        self.layout = layout
        self.grid = fz.rasterize(layout.hall, layout.obstacles)
        self.clear = fz.clearance(self.grid)
        self.footprint = fz.robot_footprint()
        self.labels = fz.reachable_components(
            self.grid, self.footprint.half_width + fz.PATH_MARGIN_M
        )
        self.start_label = 0
        self.goals: list[fz.Pose2D] = []

    @classmethod
    def of(cls, world: WorldDescription, rng: np.random.Generator) -> _Sampler:
        """A sampler on a world already made (its layout, the robot's start region)."""
        sampler = cls(rng, Layout(world.hall, world.obstacles, world.surfaces))
        sampler.start_label = sampler.label_at(world.robot_start.x, world.robot_start.y)
        return sampler

    def label_at(self, x: float, y: float) -> int:
        cell = fz.cell_of(self.grid, x, y)
        return int(self.labels[cell]) if cell is not None else 0

    def goal_ok(self, pose: fz.Pose2D) -> bool:
        """A free footprint, in the start's component."""
        free = fz.footprint_free(self.grid, pose, self.footprint)
        return free and self.label_at(pose.x, pose.y) == self.start_label

    def random_free_point(self, min_clearance: float) -> tuple[float, float] | None:
        """A uniformly drawn point whose cell has `min_clearance` and is in the start's region."""
        mask = self.clear >= min_clearance
        if self.start_label:
            mask &= self.labels == self.start_label
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return None
        iy, ix = np.unravel_index(int(idx[self.rng.integers(idx.size)]), mask.shape)
        res, (x0, y0) = self.grid.resolution, self.grid.origin
        x = x0 + (ix + uniform(self.rng)) * res
        y = y0 + (iy + uniform(self.rng)) * res
        return float(x), float(y)

    def robot_start(self) -> RobotStart | None:
        fp = self.footprint
        turn = math.hypot(max(fp.front, fp.back), fp.half_width) + 0.2
        labels, counts = np.unique(self.labels[self.labels > 0], return_counts=True)
        if labels.size == 0:
            return None
        self.start_label = int(labels[np.argmax(counts)])  # the main floor, not a pocket
        point = self.random_free_point(turn)
        if point is None:
            return None
        return RobotStart(point[0], point[1], uniform(self.rng, -math.pi, math.pi))

    def depth_max(self) -> float:
        """How far in from a surface's edge an artifact may stand: the pick pose's
        footprint must stay off the surface (see feasibility.footprint_free)."""
        room = robot.D_OPT_M - self.footprint.front - fz.GOAL_MARGIN_M - self.grid.resolution
        return min(EDGE_DEPTH_M[1], room - 0.01)

    def pick_poses(self, artifact: Artifact, surface: SupportSurface) -> list[fz.Pose2D] | None:
        """The artifact's standoff poses, when the robot can stand at them (else None)."""
        poses = [
            fz.standoff_pose_for(artifact, surface, distance, robot.THETA_OPT_RAD)
            for distance in (robot.STANDOFF_DISTANCE_M, robot.D_OPT_M)
        ]
        return poses if all(self.goal_ok(pose) for pose in poses) else None

    def artifacts(self, classes: Sequence[ArtifactClass], tries: int = 80) -> list[Artifact] | None:
        depth_max = self.depth_max()
        counts: dict[str, int] = {}
        placed: list[Artifact] = []
        for cls in classes:
            for _ in range(tries):
                surface = self.layout.surfaces[int(self.rng.integers(len(self.layout.surfaces)))]
                artifact = self._on_edge(cls, surface, counts.get(cls, 0) + 1, depth_max)
                if artifact is None or any(
                    a.surface_id == surface.id
                    and math.dist(a.position[:2], artifact.position[:2]) < ARTIFACT_SPACING_M
                    for a in placed
                ):
                    continue
                poses = self.pick_poses(artifact, surface)
                if poses is not None:
                    counts[cls] = counts.get(cls, 0) + 1
                    placed.append(artifact)
                    self.goals.extend(poses)
                    break
            else:
                return None
        return placed

    def _on_edge(
        self,
        cls: ArtifactClass,
        surface: SupportSurface,
        n: int,
        depth_max: float,
        body: tuple[Cylinder | Cuboid, float, Rgba] | None = None,
    ) -> Artifact | None:
        """An artifact near one of the surface's long edges (local +-y), or None if none
        fits; `body`: its shape, mass and colour (None: drawn for a new one)."""
        shape, mass, rgba = body or artifact_body(self.rng, cls)
        depth_min = max(EDGE_DEPTH_M[0], _footprint_radius(shape) + 0.02)
        if depth_max < depth_min:
            return None
        depth = uniform(self.rng, depth_min, depth_max)
        hx, hy = surface.half_extents
        side = 1.0 if self.rng.random() < 0.5 else -1.0
        room = hx - depth - 0.05  # stay nearer the long edge than the short ones
        if room <= 0 or depth >= hy:
            return None
        u, v = uniform(self.rng, -room, room), side * (hy - depth)
        c, s = math.cos(surface.yaw), math.sin(surface.yaw)
        x = surface.centre_xy[0] + c * u - s * v
        y = surface.centre_xy[1] + s * u + c * v
        return Artifact(
            id=f"{cls}_{n}",
            object_class=cls,
            position=(x, y, surface.top_height),
            yaw=uniform(self.rng, -math.pi, math.pi),
            shape=shape,
            mass=mass,
            rgba=rgba,
            surface_id=surface.id,
        )

    def people(self, count: int, tries: int = 100) -> list[Person] | None:
        placed: list[Person] = []
        distance = fz.handover_distance()
        for n in range(1, count + 1):
            for _ in range(tries):
                person = self._person(n, placed, distance)
                if person is not None:
                    placed.append(person)
                    self.goals.append(fz.handover_pose_for(person.position, person.yaw, distance))
                    break
            else:
                return None
        return placed

    def _person(self, n: int, placed: list[Person], distance: float) -> Person | None:
        point = self.random_free_point(PERSON_CLEARANCE_M + PERSON_RADIUS_M)
        if point is None:
            return None
        keep_out = [(g.x, g.y) for g in self.goals] + [p.position for p in placed]
        if any(math.dist(point, q) < PERSON_SPACING_M for q in keep_out):
            return None
        yaw0 = uniform(self.rng, -math.pi, math.pi)
        for k in range(8):  # turn the person until the robot has room in front of them
            yaw = math.remainder(yaw0 + k * math.pi / 4, math.tau)
            handover = fz.handover_pose_for(point, yaw, distance)
            if self.goal_ok(handover) and all(
                math.dist((handover.x, handover.y), q) >= 1.0 for q in keep_out
            ):
                break
        else:
            return None
        return Person(
            id=f"person_{n}",
            position=point,
            yaw=yaw,
            height=uniform(self.rng, 1.6, 1.95),
            shirt_rgba=colour(self.rng, SHIRT_COLOURS),
            trousers_rgba=colour(self.rng, TROUSERS_COLOURS),
            skin_rgba=colour(self.rng, SKIN_COLOURS, jitter=0.02),
        )

    def route(self, person: Person) -> Person:
        """`person` with a route (waypoints) and a walking speed; none when no leg fits."""
        waypoints = self._waypoints(person.position)
        speed = uniform(self.rng, 0.5, MAX_WALKING_SPEED_MPS) if waypoints else 0.0
        return msgspec.structs.replace(person, waypoints=waypoints, speed=speed)

    def _waypoints(self, start: tuple[float, float]) -> tuple[tuple[float, float], ...]:
        """One to three points, each reached from the last along a line clear of obstacles."""
        points: list[tuple[float, float]] = []
        last = start
        for _ in range(int(self.rng.integers(1, 4))):
            for _ in range(30):
                point = self.random_free_point(0.8)
                if (
                    point is not None
                    and math.dist(point, last) >= 2.0
                    and self._clear_line(last, point, 0.6)
                ):
                    points.append(point)
                    last = point
                    break
        return tuple(points)

    def _clear_line(self, a: tuple[float, float], b: tuple[float, float], min_clear: float) -> bool:
        steps = max(2, int(math.dist(a, b) / (0.5 * self.grid.resolution)))
        for t in np.linspace(0.0, 1.0, steps):
            cell = fz.cell_of(self.grid, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
            if cell is None or self.clear[cell] < min_clear:
                return False
        return True


def _sample(rng: np.random.Generator, seed: int, name: str) -> WorldDescription | None:
    layouts: dict[str, Callable[[np.random.Generator], Layout]] = {
        "hall": hall_layout,
        "small": small_layout,
    }
    layout = layouts[name](rng)
    if not layout.surfaces:
        return None
    sampler = _Sampler(rng, layout)
    start = sampler.robot_start() if name == "hall" else _small_start(rng, layout)
    if start is None:
        return None
    sampler.start_label = sampler.label_at(start.x, start.y)
    if name == "hall":
        extra = int(rng.integers(3, 9))
        options: list[ArtifactClass] = ["bottle", "can", "box"]
        classes: list[ArtifactClass] = ["bottle", "bottle"]
        classes += [options[int(i)] for i in rng.integers(3, size=extra)]
        n_people = int(rng.integers(2, 6))
    else:
        classes, n_people = ["bottle"], 1
    artifacts = sampler.artifacts(classes)
    people = sampler.people(n_people) if artifacts is not None else None
    if artifacts is None or people is None:
        return None
    return WorldDescription(
        name=name,
        seed=seed,
        hall=layout.hall,
        obstacles=layout.obstacles,
        surfaces=layout.surfaces,
        artifacts=tuple(artifacts),
        people=tuple(people),
        robot_start=start,
        lighting=lighting(rng, layout.hall),
        occupancy=sampler.grid,
        movables=parked_movables(layout.hall) if name == "hall" else (),
    )


#: A trolley's half extents (m): a loaded cart 1.0 × 0.6 m, 0.9 m tall (the trunk's
#: lidars and the cameras see it), and its colour.
TROLLEY_HALF_M = (0.5, 0.3, 0.45)
TROLLEY_RGBA = (0.22, 0.33, 0.52, 1.0)
#: Movables are parked this far beyond the hall's −x wall (m), out of every sensor's reach.
MOVABLE_PARK_M = 20.0


def parked_movables(hall: Hall) -> tuple[Obstacle, ...]:
    """The hall's movables, parked (`WorldDescription.movables`): one trolley. Drawn from
    no random stream, so the rest of a seed's world is what it was without them."""
    hz = TROLLEY_HALF_M[2]
    centre = (hall.min_xy[0] - MOVABLE_PARK_M, hall.min_xy[1], hz)
    return (Obstacle("trolley_1", "trolley", centre, TROLLEY_HALF_M, 0.0, TROLLEY_RGBA),)


#: An aisle spot for a movable: at most this far from the nearest static obstacle (m: in
#: an aisle or beside furniture, not in the open), this far from the robot, a person or
#: an artifact (m), and its footprint this far clear of obstacles (m).
AISLE_NEAR_M = 1.2
AISLE_KEEP_M = 1.5
AISLE_MARGIN_M = 0.1


def aisle_spot(
    world: WorldDescription,
    movable_id: str,
    rng: np.random.Generator,
    robot_pose: tuple[float, float, float],
    keep_clear: Sequence[tuple[float, float]] = (),
    tries: int = 200,
) -> tuple[float, float, float] | None:
    """Where somebody could leave the movable `movable_id` in an aisle (the changing
    hall): (x, y, yaw) on free floor within `AISLE_NEAR_M` of the static obstacles, its
    footprint `AISLE_MARGIN_M` clear of them, `AISLE_KEEP_M` from the robot and the points
    `keep_clear` (people, artifacts), and every goal of the world (each artifact's standoff
    and pick pose, each person's handover pose) that is reachable from the robot's pose
    without it reachable with it there; None when no such spot was drawn in `tries`."""
    movable = next(m for m in world.movables if m.id == movable_id)
    grid = world.occupancy
    near = fz.clearance(grid)
    xs, ys = fz.cell_centres(grid)
    iy, ix = np.nonzero(
        (near > 0.5 * movable.half_size[1] + AISLE_MARGIN_M) & (near <= AISLE_NEAR_M)
    )
    x, y, yaw = robot_pose
    others = [(x, y), *keep_clear]
    here = msgspec.structs.replace(world, robot_start=RobotStart(x, y, yaw))
    # What is unreachable already (a walking person's handover pose on a table's corner,
    # the robot's own spot in a tight corner) is not the trolley's doing.
    before = set(fz.check_paths(here))
    for _ in range(tries if len(iy) else 0):
        k = int(rng.integers(len(iy)))
        cx, cy, cyaw = float(xs[ix[k]]), float(ys[iy[k]]), float(rng.uniform(-math.pi, math.pi))
        if any(math.dist((cx, cy), q) < AISLE_KEEP_M for q in others):
            continue
        placed = msgspec.structs.replace(movable, centre=(cx, cy, movable.centre[2]), yaw=cyaw)
        hx, hy = movable.half_size[0] + AISLE_MARGIN_M, movable.half_size[1] + AISLE_MARGIN_M
        box = fz.rect_mask(xs, ys, (cx, cy), cyaw, (-hx, hx), (-hy, hy))
        if np.any(as_numpy(grid.cells)[box] != fz.FREE):
            continue
        with_it = msgspec.structs.replace(
            here,
            obstacles=(*world.obstacles, placed),
            occupancy=fz.rasterize(world.hall, (*world.obstacles, placed), grid.resolution),
        )
        if not set(fz.check_paths(with_it)) - before:
            return cx, cy, cyaw
    return None


def _small_start(rng: np.random.Generator, layout: Layout) -> RobotStart:
    """A few metres from the small world's table, roughly facing it."""
    table = layout.surfaces[0]
    x = table.centre_xy[0] - uniform(rng, 2.5, 3.2)
    return RobotStart(x, uniform(rng, -0.5, 0.5), uniform(rng, -0.3, 0.3))


def generate_world(seed: int, name: str = "hall", walking_people: bool = False) -> WorldDescription:
    """The world `name` for `seed`: the same arguments give the same description.

    Raises ValueError for an unknown name and WorldGenerationError when no feasible sample
    was found in `MAX_ATTEMPTS`.
    """
    if name not in WORLD_NAMES:
        raise ValueError(f"unknown world {name!r}; known: {WORLD_NAMES}")
    rng = np.random.default_rng(seed)
    problems: list[str] = ["no sample placed everything"]
    for attempt in range(MAX_ATTEMPTS):
        world = _sample(rng, seed, name)
        if world is None:
            continue
        problems = fz.check_paths(world)
        if not problems:
            log.debug("world %s seed %d: feasible after %d samples", name, seed, attempt + 1)
            return with_routes(world) if walking_people else world
        log.debug("world %s seed %d sample %d dropped: %s", name, seed, attempt + 1, problems)
    raise WorldGenerationError(name, seed, problems)


def with_routes(world: WorldDescription) -> WorldDescription:
    """`world` with its people walking: each gets one to three waypoints and a speed,
    drawn from a stream of their own (`WALK_STREAM`), so that people start where they
    stand, and wear what they wear, with walking on or off; a map explored in the standing
    world is the walking world's map too."""
    rng = np.random.default_rng([world.seed, WALK_STREAM])
    sampler = _Sampler.of(world, rng)
    return msgspec.structs.replace(world, people=tuple(sampler.route(p) for p in world.people))


def new_place(
    world: WorldDescription,
    artifact_id: str,
    rng: np.random.Generator,
    taken: Sequence[tuple[float, float]],
    avoid_surface: str = "",
    tries: int = 80,
) -> tuple[tuple[float, float, float], float, str] | None:
    """Where somebody could put an artifact down instead (the changing hall): a spot near
    a long edge of a surface other than `avoid_surface`, `ARTIFACT_SPACING_M` clear of
    the points `taken`, from which the robot could pick it, as the generator places
    artifacts: (its base's point, yaw, the surface's id), or None when none fits."""
    art = next(a for a in world.artifacts if a.id == artifact_id)
    sampler = _Sampler.of(world, rng)
    surfaces = [s for s in world.surfaces if s.id != avoid_surface]
    depth_max = sampler.depth_max()
    for _ in range(tries if surfaces else 0):
        surface = surfaces[int(rng.integers(len(surfaces)))]
        spot = sampler._on_edge(
            art.object_class, surface, 0, depth_max, (art.shape, art.mass, art.rgba)
        )
        if spot is None or any(math.dist(spot.position[:2], q) < ARTIFACT_SPACING_M for q in taken):
            continue
        if sampler.pick_poses(spot, surface) is not None:
            return spot.position, spot.yaw, surface.id
    return None
