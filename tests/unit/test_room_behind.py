"""`services.mission.room_behind`: how far the base can back up on the map's grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.mission.room_behind import OCCUPIED, room_behind

BOUNDS = (-0.6, 0.5, -0.3, 0.3)  # a footprint 1.1 x 0.6 m about the base


def room(xy: tuple[float, float], yaw: float, want_m: float = 0.5) -> float:
    cells = np.zeros((100, 100), np.uint8)  # 5 x 5 m from (-2.5, -2.5), 5 cm cells
    cells[:, 30:32] = OCCUPIED  # a wall at x = -1.0 .. -0.9 m
    return room_behind(cells, 0.05, (-2.5, -2.5), xy, yaw, want_m, bounds=BOUNDS)


def test_the_back_off_stops_short_of_a_wall_behind() -> None:
    # rear edge at x = -0.6 + 0.1 = -0.5: the wall's face 0.4 m behind, less the margin
    assert room((0.1, 0.0), 0.0) == pytest.approx(0.35, abs=0.03)
    assert room((0.1, 0.0), 0.0, want_m=0.15) == 0.15  # wanted less than there is
    assert room((-0.25, 0.0), 0.0) == pytest.approx(0.0, abs=0.03)  # 0.05 m from it: none


def test_facing_away_from_the_wall_there_is_room_and_sideways_only_the_width_counts() -> None:
    assert room((0.1, 0.0), math.pi) == 0.5  # its back to the open hall
    # turned 90°: backing up runs along the wall, its side 0.4 m off the footprint's
    assert room((-0.2, 0.0), math.pi / 2) == 0.5
