"""The pick trial's way round a table: clear lines stay straight, blocked ones go round."""

from __future__ import annotations

import itertools
import math

import numpy as np

from bench.trial_pick import crosses_box, route_around
from common.messages.world import Obstacle

TABLE = Obstacle(
    id="table_1",
    kind="table",
    centre=(1.8, 0.4, 0.4),
    half_size=(0.7, 0.4, 0.4),
    yaw=math.radians(84.0),
    rgba=(0.5, 0.4, 0.3, 1.0),
)


def test_a_segment_through_the_table_crosses_it_and_one_beside_it_does_not() -> None:
    assert crosses_box(np.array([-1.0, 0.4]), np.array([4.0, 0.4]), TABLE, 0.0)
    assert not crosses_box(np.array([-1.0, 2.0]), np.array([4.0, 2.0]), TABLE, 0.0)
    assert crosses_box(np.array([-1.0, 1.4]), np.array([4.0, 1.4]), TABLE, 0.5)  # grown


def test_a_clear_line_is_its_own_route() -> None:
    goal = np.array([0.9, -0.6])
    route = route_around(np.array([-1.0, 0.0]), goal, TABLE, 0.75)
    assert len(route) == 1 and np.allclose(route[0], goal)


def test_a_blocked_line_goes_round_the_table_by_the_shorter_side_with_clearance() -> None:
    start, goal = np.array([-1.3, 0.0]), np.array([3.3, 0.45])
    route = route_around(start, goal, TABLE, 0.75)
    assert len(route) >= 2 and np.allclose(route[-1], goal)
    legs = [start, *route]
    for a, b in itertools.pairwise(legs):
        assert not crosses_box(a, b, TABLE, 0.7)  # every leg keeps its clearance
    # The start is below the table's centre line: it goes round the lower (−y) side.
    assert all(p[1] < TABLE.centre[1] for p in route[:-1])
