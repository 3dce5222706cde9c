"""The simulator's world: layout, artifacts, people, lighting and occupancy (sim truth).

One `WorldDescription` is what `dume/world/description` serves. It is static: generated
once from a seed before t = 0, so it carries no stamp. Everything is in the `world`
frame: z up, metres, yaw in radians about +z (0 = facing +x, counter-clockwise positive),
colours as linear RGBA in [0, 1]. Only the sim, the map's `seed-from-world` mode, tests
and evaluation may read it. Arrays travel as `Array` (see `common.messages.arrays`).
"""

from __future__ import annotations

from typing import Literal

import msgspec

from common.messages.arrays import Array

ObstacleKind = Literal["wall", "rack", "bench", "table", "pallet", "machine", "trolley"]
ArtifactClass = Literal["bottle", "can", "box"]

#: An RGBA colour, each channel in [0, 1].
Rgba = tuple[float, float, float, float]
#: A point or vector in the world frame, metres.
Vec3 = tuple[float, float, float]
#: A point on the floor (x, y) in the world frame, metres.
Vec2 = tuple[float, float]

#: Occupancy cell values.
FREE: int = 0
OCCUPIED: int = 100


class Hall(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The hall's interior, an axis-aligned rectangle on the floor (z = 0).

    min_xy: (2,) m, world: the interior's lower-left corner (inner faces of the walls).
    max_xy: (2,) m, world: the interior's upper-right corner.
    wall_height: m, height of the perimeter walls.
    """

    min_xy: Vec2
    max_xy: Vec2
    wall_height: float


class Obstacle(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A static obstacle: an oriented box standing on the floor.

    id: `<kind>_<n>`, numbered per kind from 1 (`wall_1`, `table_2`).
    kind: what it is; tables and benches are also listed as `SupportSurface`s.
    centre: (3,) m, world: the box centre (its bottom is at z = centre[2] - half_size[2]).
    half_size: (3,) m, box frame: half extents along the box's own x, y, z.
    yaw: rad, box frame x axis relative to world x.
    rgba: the colour it is drawn in.
    """

    id: str
    kind: ObstacleKind
    centre: Vec3
    half_size: Vec3
    yaw: float
    rgba: Rgba


class SupportSurface(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The horizontal top of a table or bench, where artifacts stand.

    id: the id of the `Obstacle` whose top this is (`table_1`, `bench_2`).
    centre_xy: (2,) m, world: the top's centre on the floor plane.
    half_extents: (2,) m, surface frame: half length along the surface's x, half depth
        along its y.
    yaw: rad, the surface frame's x axis relative to world x.
    top_height: m, z of the top face in the world.
    """

    id: str
    centre_xy: Vec2
    half_extents: Vec2
    yaw: float
    top_height: float


class Cylinder(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag="cylinder"):
    """An upright cylinder (bottles and cans).

    radius: m.
    height: m, from the base to the top (a bottle's neck included).
    """

    radius: float
    height: float


class Cuboid(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag="cuboid"):
    """A box.

    half_size: (3,) m, object frame: half extents along the object's x, y, z; the
        object's y is the narrow grasp direction (half_size[1] <= 0.035).
    """

    half_size: Vec3

    @property
    def height(self) -> float:
        """m, from the bottom face to the top (as `Cylinder.height`)."""
        return 2.0 * self.half_size[2]


class Artifact(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A graspable object standing upright on a support surface.

    id: `<class>_<n>`, numbered per class from 1 (`bottle_1`, `can_1`, `box_2`).
    object_class: its class.
    position: (3,) m, world: centre of the object's base, on the surface's top.
    yaw: rad, the object frame's x axis relative to world x.
    shape: its geometry, in the object frame (origin at the base centre, z up).
    mass: kg.
    rgba: the colour of its body.
    surface_id: the id of the `SupportSurface` it stands on.
    """

    id: str
    object_class: ArtifactClass
    position: Vec3
    yaw: float
    shape: Cylinder | Cuboid
    mass: float
    rgba: Rgba
    surface_id: str


class Person(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A worker, standing or walking between waypoints.

    id: `person_<n>`, numbered from 1.
    position: (2,) m, world: the point on the floor between the feet at t = 0.
    yaw: rad, the direction the person faces at t = 0.
    height: m, top of the head above the floor.
    shirt_rgba, trousers_rgba, skin_rgba: the colours of the torso and arms, the legs,
        the head and hands.
    waypoints: (k, 2) m, world: floor points walked in order then back, starting from
        `position`; empty for a standing person.
    speed: m/s, walking speed along the waypoints, 0 when standing, at most 1.2.
    """

    id: str
    position: Vec2
    yaw: float
    height: float
    shirt_rgba: Rgba
    trousers_rgba: Rgba
    skin_rgba: Rgba
    waypoints: tuple[Vec2, ...] = ()
    speed: float = 0.0


class RobotStart(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Where the robot stands at t = 0.

    x, y: m, world: the base origin projected on the floor.
    yaw: rad, the base heading.
    """

    x: float
    y: float
    yaw: float


class Light(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A ceiling light pointing down (drawn without shadows).

    position: (3,) m, world.
    direction: (3,) unit vector, world: where it points.
    diffuse: (3,) RGB in [0, 1].
    specular: (3,) RGB in [0, 1].
    directional: True for a directional light, False for a spot light.
    """

    position: Vec3
    direction: Vec3
    diffuse: Vec3
    specular: Vec3
    directional: bool


class Lighting(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The scene's lights.

    ambient: (3,) RGB in [0, 1]: light everywhere (MuJoCo's headlight ambient).
    headlight_diffuse: (3,) RGB in [0, 1]: the light that follows each camera.
    lights: the ceiling lights.
    """

    ambient: Vec3
    headlight_diffuse: Vec3
    lights: tuple[Light, ...]


class OccupancyGrid(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The static obstacles rasterized on the floor (people are not in it).

    resolution: m, the side of one square cell (0.05).
    origin: (2,) m, world: the outer corner of cell [0, 0] (its minimal x and y).
    cells: uint8 (ny, nx): `cells[iy, ix]` is 0 (free) or 100 (occupied); cell (ix, iy)
        spans origin + (i, i + 1) * resolution on each axis, its centre is
        origin + (i + 0.5) * resolution. A cell is occupied when an obstacle's footprint
        overlaps it.
    """

    resolution: float
    origin: Vec2
    cells: Array


class WorldDescription(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A whole world: what the sim builds and what evaluation compares against.

    name: the generator's world kind (`hall`, `small`).
    seed: the generator's seed; the same name and seed give the same description.
    hall: the interior extents.
    obstacles: every static obstacle, walls included.
    surfaces: the tops of the tables and benches.
    artifacts: the graspable objects, each on one of `surfaces`.
    people: the workers.
    robot_start: the robot's pose at t = 0.
    lighting: the lights.
    occupancy: the static obstacles on a grid.
    movables: obstacles somebody may leave in an aisle (a trolley: the changing hall),
        parked beyond the hall's walls (`centre`) until the sim's hook moves one in
        (`dume/world/obstacle_command`); on no floor plan and not in `occupancy`.
    """

    name: str
    seed: int
    hall: Hall
    obstacles: tuple[Obstacle, ...]
    surfaces: tuple[SupportSurface, ...]
    artifacts: tuple[Artifact, ...]
    people: tuple[Person, ...]
    robot_start: RobotStart
    lighting: Lighting
    occupancy: OccupancyGrid
    movables: tuple[Obstacle, ...] = ()
