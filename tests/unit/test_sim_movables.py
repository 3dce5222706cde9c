"""The changing hall's movables: a trolley parked beyond the walls, left in an aisle by the
sim's hook (`dume/world/movable_command`), seen by the robot's sensors where it stands."""

from __future__ import annotations

import logging
import math

import msgspec
import numpy as np
import pytest

from common.messages import as_numpy
from common.messages.sim import MovableCommand
from common.messages.world import WorldDescription
from services.sim import feasibility as fz
from services.sim.artifact_hook import MovableHook
from services.sim.core import SimCore
from services.sim.sensors import ideal_sensors
from services.sim.world import AISLE_KEEP_M, AISLE_NEAR_M, aisle_spot, generate_world


@pytest.fixture(scope="module")
def hall() -> WorldDescription:
    return generate_world(0)


def test_the_hall_has_a_trolley_parked_beyond_its_walls_and_the_small_world_none(
    hall: WorldDescription,
) -> None:
    (trolley,) = hall.movables
    assert (trolley.id, trolley.kind) == ("trolley_1", "trolley")
    assert trolley.centre[0] < hall.hall.min_xy[0] - 10.0  # out of every sensor's reach
    assert trolley.id not in {o.id for o in hall.obstacles}  # on no floor plan
    assert generate_world(0, "small").movables == ()


def _start(world: WorldDescription) -> tuple[float, float, float]:
    s = world.robot_start
    return s.x, s.y, s.yaw


def test_an_aisle_spot_is_free_near_furniture_clear_of_the_robot_and_keeps_every_goal(
    hall: WorldDescription,
) -> None:
    people = [p.position[:2] for p in hall.people]
    spot = aisle_spot(hall, "trolley_1", np.random.default_rng(1), _start(hall), people)
    assert spot is not None
    x, y, yaw = spot
    near = fz.clearance(hall.occupancy)
    cell = fz.cell_of(hall.occupancy, x, y)
    assert cell is not None and 0.0 < near[cell] <= AISLE_NEAR_M + 1e-9
    assert all(math.dist((x, y), q) >= AISLE_KEEP_M for q in [_start(hall)[:2], *people])
    # Its footprint on free floor, and every goal still reachable with it there.
    (trolley,) = hall.movables
    xs, ys = fz.cell_centres(hall.occupancy)
    hx, hy = trolley.half_size[:2]
    box = fz.rect_mask(xs, ys, (x, y), yaw, (-hx, hx), (-hy, hy))
    assert box.any() and not np.any(as_numpy(hall.occupancy.cells)[box] != fz.FREE)
    assert aisle_spot(hall, "trolley_1", np.random.default_rng(1), _start(hall), people) == spot


def test_a_trolley_left_in_front_of_the_robot_stands_there_and_the_lidar_sees_it(
    hall: WorldDescription,
) -> None:
    core = SimCore(hall, locomotion="kinematic", sensors=ideal_sensors())
    x, y, yaw = _start(hall)
    ahead = (x + 2.0 * math.cos(yaw), y + 2.0 * math.sin(yaw))
    before = core.lidar.scan(core.data)
    front = int(np.argmin(np.abs(core.lidar.angles)))
    assert core.place_movable("trolley_1", ahead, yaw + math.pi / 2) == ahead
    core.step()
    after = core.lidar.scan(core.data)
    # The trolley's near face stands 2 m − 0.3 m (its half depth) ahead of the base; the
    # lidar sits on the trunk's front, so its beam ends sooner than 1.7 m.
    assert 0.9 < after[front] < 1.7, (before[front], after[front])
    assert before[front] == 0.0 or before[front] > after[front] + 0.1
    # Parked away again: the beam passes where it stood.
    cx, _ = core.place_movable("trolley_1", None, 0.0)
    core.step()
    assert cx < hall.hall.min_xy[0] - 10.0
    assert np.array_equal(core.lidar.scan(core.data), before)


def test_a_bad_movable_command_is_refused_and_moves_nothing(hall: WorldDescription) -> None:
    core = SimCore(hall, locomotion="kinematic", sensors=ideal_sensors())
    with pytest.raises(KeyError, match="trolley_9"):
        core.place_movable("trolley_9", (0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="hall's floor"):
        core.place_movable("trolley_1", (math.nan, 0.0), 0.0)
    with pytest.raises(ValueError, match="hall's floor"):
        core.place_movable("trolley_1", (hall.hall.max_xy[0] + 5.0, 0.0), 0.0)


class _Fifo:
    def __init__(self, items: list[MovableCommand]) -> None:
        self.items = items

    def drain(self) -> list[MovableCommand]:
        out, self.items = self.items, []
        return out


def test_the_hook_leaves_it_at_the_stamp_reports_the_move_and_refuses_a_bad_command(
    hall: WorldDescription,
) -> None:
    core = SimCore(hall, locomotion="kinematic", sensors=ideal_sensors())
    x, y, _ = _start(hall)
    hook = MovableHook.__new__(MovableHook)
    hook._fifo = _Fifo([  # type: ignore[assignment]
        MovableCommand(stamp_ns=2_000_000, movable_id="trolley_1", position=(x + 2.0, y)),
        MovableCommand(stamp_ns=1_000_000, movable_id="trolley_9", away=True),
        MovableCommand(stamp_ns=1_000_000, movable_id="trolley_1"),  # neither place nor away
    ])  # fmt: skip
    hook._pending, hook.log, hook.applied = [], logging.getLogger("test"), 0
    assert hook.apply(0, core) == []
    assert hook.apply(1_000_000, core) == [] and hook.applied == 0
    moved = hook.apply(2_000_000, core)
    assert [(m.movable_id, m.position_in_world, m.away) for m in moved] == [
        ("trolley_1", (x + 2.0, y), False)
    ]


def test_a_goal_unreachable_already_does_not_keep_the_trolley_out(hall: WorldDescription) -> None:
    """A walking person faces a wall from 0.3 m (their handover pose lies in the wall):
    that is no reason to leave the trolley nowhere (the shift's first trolley was never
    left: every spot was refused for such a goal)."""
    p = hall.people[0]
    at_wall = msgspec.structs.replace(
        p, position=(hall.hall.min_xy[0] + 0.3, p.position[1]), yaw=math.pi
    )
    world = msgspec.structs.replace(hall, people=(at_wall, *hall.people[1:]))
    assert any(p.id in problem for problem in fz.check_paths(world))
    spot = aisle_spot(world, "trolley_1", np.random.default_rng(1), _start(world))
    assert spot is not None
