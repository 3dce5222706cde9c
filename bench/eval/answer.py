"""The requested worker answers the robot's ask (`dume eval --shift`, the human's part).

When the mission cannot find the person it brings something to, it turns round, then
asks for them on its status ("asking for person_5: please come to the robot": a speaker,
a screen). A worker who asked for a part and hears the robot call them walks over. The
shift plays that worker from the simulator's truth, as it plays the bystanders, the
moves and the slips: at the first status of each ask (`Answer.on_progress`), when the
request's truth person stands within `HEAR_M` of the robot and can walk to it straight
(round its side when they stand behind it: `answer_walk`, every leg `PERSON_CLEAR_M`
clear of the world's static obstacles), they walk (`dume/world/people_command`, stamped
`REACT_S` after the ask: a shift repeats as one request does) to `IN_FRONT_M` in front
of the robot's base and stand there, then face it (a second command, stamped after the
walk's time: `walk_s`). Nothing here reaches the robot but what its sensors see: the
mission decides from its map who came (`LookForPerson`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from common.geometry import yaw_of_quat_xyzw
from common.messages.mission import MissionStatus
from common.messages.sim import PeopleTruth, PersonCommand, StateTruth
from common.messages.world import OccupancyGrid
from services.sim import feasibility as fz

#: m: how far from the robot a worker hears it ask.
HEAR_M = 8.0
#: s from the ask to the worker's first step (they hear it, turn and walk).
REACT_S = 2.0
#: m/s the worker walks over at.
SPEED_MPS = 1.0
#: m in front of the base where the worker stops (in the head camera's view).
IN_FRONT_M = 1.3
#: m: round the robot's side (from its base) when the worker comes from behind it.
SIDE_M = 1.4
#: m a worker's walk keeps from the static obstacles (their body's half width).
PERSON_CLEAR_M = 0.3
#: m between the points a walk's legs are checked at.
STEP_M = 0.05

Point = tuple[float, float]


def answer_walk(person: Point, base: tuple[float, float, float]) -> list[Point]:
    """The points a worker at `person` walks to reach `IN_FRONT_M` in front of the base
    at (x, y, yaw): straight there from its front half, else first to `SIDE_M` beside
    it on their side (never through the robot)."""
    x, y, yaw = base
    c, s = math.cos(yaw), math.sin(yaw)
    front = (x + IN_FRONT_M * c, y + IN_FRONT_M * s)
    ahead = c * (person[0] - x) + s * (person[1] - y)
    if ahead > 0.0:
        return [front]
    left = -s * (person[0] - x) + c * (person[1] - y)
    side = math.copysign(SIDE_M, left)
    return [(x - side * s, y + side * c), front]


def walk_clear(grid: OccupancyGrid, clearance: np.ndarray, points: Sequence[Point]) -> bool:
    """Whether every leg between consecutive `points` keeps `PERSON_CLEAR_M` from the
    static obstacles of `grid` (`clearance`: `feasibility.clearance(grid)`)."""
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        n = max(1, math.ceil(math.dist((x0, y0), (x1, y1)) / STEP_M))
        for k in range(n + 1):
            cell = fz.cell_of(grid, x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n)
            if cell is None or clearance[cell] < PERSON_CLEAR_M:
                return False
    return True


def walk_s(start: Point, points: Sequence[Point]) -> float:
    """Sim seconds a worker takes to walk `points` from `start` and stand: the legs at
    `SPEED_MPS`, a second more for each to speed up and slow down, and a turn of at
    most π at `services.sim.people.TURN_RATE_RADPS` (2 rad/s) before each."""
    legs = list(itertools.pairwise([start, *points]))
    return sum(math.dist(a, b) / SPEED_MPS + 1.0 + math.pi / 2.0 for a, b in legs)


class Answer:
    """One request's worker answering the robot's asks (the module docstring): call
    `on_progress` as the request runs; `said` holds what happened, for the report."""

    def __init__(
        self,
        statuses: Any,
        follow: Any,
        commands: Any,
        grid: OccupancyGrid,
        request_id: str,
        map_person: str,
        truth_person: str,
    ) -> None:
        self.statuses, self.follow, self.commands = statuses, follow, commands
        self.grid, self.clearance = grid, fz.clearance(grid)
        self.request_id, self.map_person, self.truth_person = request_id, map_person, truth_person
        self.asking = False
        self.answered = False  # a worker answers once a request
        self.said: list[str] = []

    def on_progress(self, *_: object) -> None:
        self.follow.drain()
        for status in self.statuses.drain():
            if isinstance(status, MissionStatus) and status.request_id == self.request_id:
                self._status(status)

    def _status(self, status: MissionStatus) -> None:
        asking = status.detail.startswith(f"asking for {self.map_person}")
        if asking and not self.asking and self.truth_person and not self.answered:
            self._hear(status.stamp_ns)
        self.asking = asking

    def _hear(self, t_ns: int) -> None:
        people: PeopleTruth | None = self.follow.people_at(t_ns)
        base: StateTruth | None = self.follow.base_at(t_ns)
        who = (
            None
            if people is None
            else next((p for p in people.people if p.id == self.truth_person), None)
        )
        if who is None or base is None:
            return
        x, y, _ = base.base_position_in_world
        pose = (x, y, yaw_of_quat_xyzw(base.base_orientation_xyzw))
        d = math.dist(who.position, (x, y))
        at = f"{t_ns / 1e9:.1f} s"
        if d > HEAR_M:
            self.said.append(f"{self.truth_person} {d:.1f} m off did not hear the ask at {at}")
            return
        # Where they will be when they step off, walking on as they were.
        later = (who.position[0] + REACT_S * who.velocity[0],
                 who.position[1] + REACT_S * who.velocity[1])  # fmt: skip
        walk = answer_walk(who.position, pose)
        if not (walk_clear(self.grid, self.clearance, [who.position, *walk])
                and walk_clear(self.grid, self.clearance, [later, *walk])):  # fmt: skip
            self.said.append(f"{self.truth_person} {d:.1f} m off heard the ask at {at} but "
                             "has no straight way to the robot")  # fmt: skip
            return
        go_ns = t_ns + round(REACT_S * 1e9)
        self.commands.put(PersonCommand(stamp_ns=go_ns, person_id=self.truth_person,
                                        walk_to=tuple(walk), speed=SPEED_MPS,
                                        ignore_robot=True))  # fmt: skip
        there_ns = go_ns + round(walk_s(later, walk) * 1e9)  # then face the robot
        self.commands.put(PersonCommand(stamp_ns=there_ns, person_id=self.truth_person,
                                        ignore_robot=False))  # fmt: skip
        self.answered = True
        self.said.append(f"{self.truth_person} {d:.1f} m off heard the ask at {at} and walks "
                         f"to the robot")  # fmt: skip
