"""The shift's worker who answers the robot's ask (`bench/eval/answer.py`): who hears it,
the walk over (never through the robot or the furniture), and the two stamped people
commands that play it."""

from __future__ import annotations

import math

import numpy as np

from bench.eval.answer import (
    HEAR_M,
    IN_FRONT_M,
    REACT_S,
    SIDE_M,
    Answer,
    answer_walk,
    walk_clear,
)
from common.messages.arrays import to_wire
from common.messages.mission import MissionStatus
from common.messages.sim import PeopleTruth, PersonCommand, PersonTruth, StateTruth
from common.messages.world import OCCUPIED, OccupancyGrid
from services.sim import feasibility as fz

S = 1_000_000_000


def _grid(bench: bool = False) -> OccupancyGrid:
    """10 × 10 m of floor about the origin; with `bench`, a block across x = 2..2.8."""
    cells = np.zeros((200, 200), dtype=np.uint8)
    if bench:
        cells[60:140, 140:156] = OCCUPIED  # x 2.0..2.8, y -2..2
    return OccupancyGrid(resolution=0.05, origin=(-5.0, -5.0), cells=to_wire(cells))


def test_the_walk_goes_straight_from_the_front_and_round_the_side_from_behind() -> None:
    base = (0.0, 0.0, 0.0)
    assert answer_walk((4.0, 1.0), base) == [(IN_FRONT_M, 0.0)]
    round_left = answer_walk((-3.0, 0.5), base)
    assert np.allclose(round_left, [(0.0, SIDE_M), (IN_FRONT_M, 0.0)])
    round_right = answer_walk((3.0, -0.5), (0.0, 0.0, math.pi / 2))  # facing +y, on its right
    assert np.allclose(round_right, [(SIDE_M, 0.0), (0.0, IN_FRONT_M)])


def test_a_walk_through_furniture_is_not_clear() -> None:
    grid = _grid(bench=True)
    clearance = fz.clearance(grid)
    assert walk_clear(grid, clearance, [(-3.0, 0.0), (1.3, 0.0)])
    assert not walk_clear(grid, clearance, [(4.0, 0.0), (1.3, 0.0)])  # through the bench


class _Fifo:
    def __init__(self, items: list[object]) -> None:
        self.items = items

    def drain(self) -> list[object]:
        out, self.items = self.items, []
        return out


class _Follow:
    def __init__(self, person_xy: tuple[float, float]) -> None:
        who = PersonTruth(id="person_4", position=person_xy, yaw=0.0, velocity=(0.0, 0.0))
        self.people = PeopleTruth(stamp_ns=10 * S, people=[who])
        self.history = [self.people]

    def drain(self) -> None:
        pass

    def people_at(self, t_ns: int) -> PeopleTruth:
        return self.people

    def base_at(self, t_ns: int) -> StateTruth:
        return StateTruth(stamp_ns=t_ns, base_position_in_world=(0.0, 0.0, 0.5),
                          base_orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
                          base_linear_velocity_in_world=(0.0, 0.0, 0.0),
                          base_angular_velocity_in_base=(0.0, 0.0, 0.0))  # fmt: skip


class _Commands:
    def __init__(self) -> None:
        self.sent: list[PersonCommand] = []

    def put(self, c: PersonCommand) -> None:
        self.sent.append(c)


def _asked(person_xy: tuple[float, float], grid: OccupancyGrid) -> tuple[Answer, _Commands]:
    statuses = [
        MissionStatus(stamp_ns=9 * S, request_id="r", state="running",
                      detail="looking for person_5"),
        MissionStatus(stamp_ns=10 * S, request_id="r", state="running",
                      detail="asking for person_5: please come to the robot"),
        MissionStatus(stamp_ns=11 * S, request_id="r", state="running",
                      detail="asking for person_5: please come to the robot"),
        MissionStatus(stamp_ns=11 * S, request_id="other", state="running",
                      detail="asking for person_5: please come to the robot"),
    ]  # fmt: skip
    commands = _Commands()
    answer = Answer(_Fifo(list(statuses)), _Follow(person_xy), commands, grid, "r", "person_5",
                    "person_4")  # fmt: skip
    answer.on_progress()
    answer.on_progress()
    return answer, commands


def test_the_worker_asked_for_walks_over_once_and_then_faces_the_robot() -> None:
    answer, commands = _asked((-3.0, 0.5), _grid())
    walk, face = commands.sent
    assert walk.person_id == face.person_id == "person_4"
    assert walk.stamp_ns == 10 * S + round(REACT_S * S) and walk.ignore_robot
    assert np.allclose(walk.walk_to, [(0.0, SIDE_M), (IN_FRONT_M, 0.0)])
    assert face.stamp_ns > walk.stamp_ns + 4 * S and not face.ignore_robot and not face.walk_to
    assert "heard the ask" in answer.said[0]


def test_a_worker_out_of_earshot_or_without_a_way_does_not_come() -> None:
    answer, commands = _asked((HEAR_M + 1.0, 0.0), _grid())
    assert not commands.sent and "did not hear" in answer.said[0]
    answer, commands = _asked((4.0, 0.0), _grid(bench=True))
    assert not commands.sent and "no straight way" in answer.said[0]
