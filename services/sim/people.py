"""People in the sim: mocap bodies that walk their waypoints and turn to face the robot.

Each person is a small state machine updated every physics step with the robot's base
pose (`RobotNear`): when the base is within `FACE_RADIUS_M` the person stops and turns
towards it (a worker waiting for the robot); otherwise a walking person follows the route
`position -> waypoints[0] -> ... -> waypoints[-1] -> ... -> position -> ...` at their
speed (at most `MAX_SPEED_MPS`), pausing `PAUSE_S` at each end of a leg and turning in
place towards the next one before walking on. A walker speeds up from rest and slows
into the point they walk to at `ACCEL_MPS2`, as people do (they reach their pace in one
or two steps), and stops at once (a step). Stepping from rest straight to 1.1 m/s, a
bystander who had paused beside the robot walked past it inside the protective
separation of a speed nobody could have measured in time (the shift, t = 118 s). Turns
run at `TURN_RATE_RADPS`. With walking off, or no waypoints, a person only turns.

Bystanders (`bystanders`, with walking on: the changing hall) do not stop for the robot:
a walking person keeps to their route past it and across its path, and stops to face it
only when it comes to them holding something (within `COME_M`, its heading within
`COME_HALF_ANGLE_RAD` of them: the person asked for it, or one who sees it is for them),
then waits while it stays within `FACE_RADIUS_M`, for `WAIT_S` at most once it stops
coming nearer: a robot that stands near them with something that is not for them does
not keep them for good (it held the robot, whose goal was beside them, for two minutes
in the shift), and they wait for it again only once it has gone and comes again.
Nobody walks into a machine: a bystander who has come within `YIELD_M` of the robot's
base ahead of them (within `YIELD_HALF_ANGLE_RAD` of where they walk) pauses until it is
clear, and after `GIVE_WAY_S` of that turns back along their route (a person does not
wait for ever on a robot that waits for them: the two stood facing each other for good
in the changing hall's shift, the robot's goal inside their safety zone).

`command` (a test hook) teleports a person and/or sends them along given points once,
optionally ignoring the robot. The hand and the handover are `services.sim.handover`'s;
the hand moves with the person's body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import mujoco
import numpy as np

from common.geometry import wrap_angle
from common.messages.world import Person

FACE_RADIUS_M = 3.0
COME_M = 2.0
COME_HALF_ANGLE_RAD = math.radians(35.0)
YIELD_M = 1.1
YIELD_HALF_ANGLE_RAD = math.radians(50.0)
MAX_SPEED_MPS = 1.2
TURN_RATE_RADPS = 2.0
#: m/s²: how fast a walker speeds up from rest and slows into a point (gait initiation
#: reaches a walking pace of 1-1.4 m/s in about a second).
ACCEL_MPS2 = 1.0
PAUSE_S = 1.0
GIVE_WAY_S = 4.0
#: s a bystander waits for a robot that came to them carrying, once it comes no nearer
#: (by `NEARER_M`): the handover it came for reaches them well within that.
WAIT_S = 30.0
NEARER_M = 0.05
#: Closer than this to the next point counts as there (the last step lands on it).
ARRIVE_M = 1e-9


@dataclass
class _Walker:
    """One person's pose and progress along their route."""

    mocap: int
    x: float
    y: float
    yaw: float
    route: list[tuple[float, float]]
    speed: float
    leg: int = 0  # walking from route[leg] towards route[leg + 1] (cyclic, ping-pong)
    pause_s: float = 0.0
    dirty: bool = True  # the mocap pose needs writing
    once: bool = False  # a commanded walk: the route once, no pauses, then stand
    ignore_robot: bool = False  # walk on even with the robot within FACE_RADIUS_M
    waiting: bool = False  # a bystander stopped for the robot that came to them
    waited_s: float = 0.0  # since the robot last came nearer (`WAIT_S`)
    closest_m: float = math.inf  # the nearest the robot came while they waited
    waited_out: bool = False  # gave up on the robot near them: not again till it went
    yielding_s: float = 0.0  # how long a bystander has paused for the robot in the way
    vx: float = 0.0  # the last step's velocity, m/s (world)
    vy: float = 0.0
    pace: float = 0.0  # the speed walked at, m/s: up from rest at ACCEL_MPS2


class RobotNear(NamedTuple):
    """What people see of the robot: its base on the floor (m, rad) and whether it holds
    something up (an artifact off every surface, not in a hand)."""

    x: float
    y: float
    yaw: float = 0.0
    carrying: bool = False


def _route(person: Person) -> list[tuple[float, float]]:
    """Out along the waypoints and back, as one closed loop of points."""
    points = [person.position, *person.waypoints]
    return points + points[-2:0:-1]


class People:
    """The people of a world, moved each step (`update`) by writing their mocap poses."""

    def __init__(
        self,
        model: mujoco.MjModel,
        people: tuple[Person, ...],
        walking: bool,
        bystanders: bool = False,
    ) -> None:
        self.ids = tuple(p.id for p in people)
        self.bystanders = bystanders and walking
        self._walkers = [
            _Walker(
                mocap=int(model.body(p.id).mocapid[0]),
                x=p.position[0],
                y=p.position[1],
                yaw=p.yaw,
                route=_route(p) if walking and p.waypoints and p.speed > 0 else [],
                speed=min(p.speed, MAX_SPEED_MPS),
            )
            for p in people
        ]

    def pose(self, person_id: str) -> tuple[float, float, float]:
        """(x, y, yaw) of a person on the floor, m and rad."""
        w = self._walkers[self.ids.index(person_id)]
        return w.x, w.y, w.yaw

    def velocity(self, person_id: str) -> tuple[float, float]:
        """A person's floor velocity over the last step, m/s (world)."""
        w = self._walkers[self.ids.index(person_id)]
        return w.vx, w.vy

    def command(
        self,
        person_id: str,
        position: tuple[float, float] | None,
        yaw: float | None,
        walk_to: list[tuple[float, float]],
        speed: float,
        ignore_robot: bool,
    ) -> None:
        """A test hook (`dume/world/people_command`): teleport a person (position, yaw),
        then walk `walk_to` once at `speed` and stand; their own route is dropped.
        `ignore_robot`: no stopping to face the robot. Raises KeyError for an unknown id,
        ValueError for a bad speed."""
        if person_id not in self.ids:
            raise KeyError(f"no person {person_id!r}; the world has {list(self.ids)}")
        if not 0.0 < speed <= MAX_SPEED_MPS:
            raise ValueError(f"a person walks at (0, {MAX_SPEED_MPS}] m/s, got {speed}")
        w = self._walkers[self.ids.index(person_id)]
        if position is not None:
            w.x, w.y = float(position[0]), float(position[1])
        if yaw is not None:
            w.yaw = wrap_angle(float(yaw))
        w.route = [(w.x, w.y), *walk_to] if walk_to else []
        w.leg, w.pause_s, w.speed, w.once = 0, 0.0, speed, True
        w.ignore_robot, w.dirty = ignore_robot, True

    def update(self, data: mujoco.MjData, robot: RobotNear, dt: float) -> None:
        """Advance every person by dt seconds with the robot as given; write mocap."""
        for w in self._walkers:
            x0, y0 = w.x, w.y
            dx, dy = robot.x - w.x, robot.y - w.y
            near = dx * dx + dy * dy <= FACE_RADIUS_M * FACE_RADIUS_M
            if self.bystanders and w.route and not w.once:
                w.waiting = self._waits(w, near, robot, dt)
                if w.waiting:
                    self._turn_towards(w, math.atan2(dy, dx), dt)
                elif _in_the_way(robot, w):
                    w.yielding_s += dt
                    if w.yielding_s >= GIVE_WAY_S:
                        _turn_back(w)
                else:
                    w.yielding_s = 0.0
                    self._walk(w, dt)
            elif not w.ignore_robot and near:
                self._turn_towards(w, math.atan2(dy, dx), dt)
            elif w.route:
                self._walk(w, dt)
            w.vx, w.vy = (w.x - x0) / dt, (w.y - y0) / dt
            if w.x == x0 and w.y == y0:
                w.pace = 0.0  # stood, turned or paused: from rest again
            if w.dirty:
                data.mocap_pos[w.mocap, 0] = w.x
                data.mocap_pos[w.mocap, 1] = w.y
                data.mocap_quat[w.mocap] = (math.cos(0.5 * w.yaw), 0.0, 0.0, math.sin(0.5 * w.yaw))
                w.dirty = False

    @staticmethod
    def _waits(w: _Walker, near: bool, robot: RobotNear, dt: float) -> bool:
        """Whether a bystander waits for the robot this step (module docstring)."""
        if not near:
            w.waited_out, w.closest_m = False, math.inf
            return False
        if w.waited_out or not (w.waiting or _coming_to(robot, w)):
            return False
        distance = math.hypot(robot.x - w.x, robot.y - w.y)
        if distance < w.closest_m - NEARER_M or not w.waiting:
            w.closest_m, w.waited_s = distance, 0.0
        w.waited_s += dt
        if w.waited_s >= WAIT_S:
            w.waited_out, w.closest_m = True, math.inf
            return False
        return True

    @staticmethod
    def _turn_towards(w: _Walker, heading: float, dt: float) -> bool:
        """Turn at most TURN_RATE_RADPS * dt towards heading; True once facing it."""
        error = wrap_angle(heading - w.yaw)
        if abs(error) < 1e-6:  # facing it: leave the pose (and the mocap write) alone
            return True
        step = max(-TURN_RATE_RADPS * dt, min(TURN_RATE_RADPS * dt, error))
        w.yaw = wrap_angle(w.yaw + step)
        w.dirty = True
        return abs(error) <= TURN_RATE_RADPS * dt

    def _walk(self, w: _Walker, dt: float) -> None:
        if w.pause_s > 0.0:
            w.pause_s = max(0.0, w.pause_s - dt)
            return
        tx, ty = w.route[(w.leg + 1) % len(w.route)]
        dx, dy = tx - w.x, ty - w.y
        distance = math.hypot(dx, dy)
        if distance <= ARRIVE_M:  # there: stand on the point, pause, then the next leg
            w.x, w.y, w.dirty = tx, ty, True
            w.leg = (w.leg + 1) % len(w.route)
            if w.once and w.leg == len(w.route) - 1:
                w.route, w.leg = [], 0  # a commanded walk ends standing at its last point
                return
            w.pause_s = 0.0 if w.once else PAUSE_S
            return
        if not self._turn_towards(w, math.atan2(dy, dx), dt):
            return
        w.pace = min(w.speed, w.pace + ACCEL_MPS2 * dt, math.sqrt(2.0 * ACCEL_MPS2 * distance))
        step = min(distance, max(w.pace, ACCEL_MPS2 * dt) * dt)
        w.x += step * dx / distance
        w.y += step * dy / distance
        w.dirty = True


def _turn_back(w: _Walker) -> None:
    """Walk the route the other way from here: towards the point last left."""
    n = len(w.route)
    w.route = w.route[::-1]
    w.leg = (n - 2 - w.leg) % n  # route[leg] was the point left: now the one walked to
    w.yielding_s = 0.0


def _coming_to(robot: RobotNear, w: _Walker) -> bool:
    """The robot comes to this person holding something: near, heading at them."""
    dx, dy = w.x - robot.x, w.y - robot.y
    if not robot.carrying or dx * dx + dy * dy > COME_M * COME_M:
        return False
    return abs(wrap_angle(math.atan2(dy, dx) - robot.yaw)) <= COME_HALF_ANGLE_RAD


def _in_the_way(robot: RobotNear, w: _Walker) -> bool:
    """The robot's base stands within `YIELD_M` ahead of where this person walks."""
    if w.pause_s > 0.0:
        return False
    tx, ty = w.route[(w.leg + 1) % len(w.route)]
    dx, dy = robot.x - w.x, robot.y - w.y
    if dx * dx + dy * dy > YIELD_M * YIELD_M:
        return False
    heading = math.atan2(ty - w.y, tx - w.x)
    return abs(wrap_angle(math.atan2(dy, dx) - heading)) <= YIELD_HALF_ANGLE_RAD


def person_rotation(yaw: float) -> np.ndarray:
    """The person frame's rotation in the world (z up, x where they face)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
