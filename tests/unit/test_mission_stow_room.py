"""The stow's room: the support's edge ahead of the base, and how far the base backs off
before it folds a held object down (`services.mission.stow_room`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.robot import STAND_BASE_HEIGHT_M, posture_tcp
from services.mission.room_behind import OCCUPIED
from services.mission.stow_room import (
    BACK_OFF_MAX_M,
    MARGIN_M,
    stow_back_off_m,
    support_ahead_m,
)

RES = 0.05
ORIGIN = (-5.0, -5.0)


def grid_with(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """A 10 x 10 m grid, free but for the box [x0, x1] x [y0, y1] (world, m)."""
    cells = np.zeros((200, 200), np.uint8)
    ix0, ix1 = (round((v - ORIGIN[0]) / RES) for v in (x0, x1))
    iy0, iy1 = (round((v - ORIGIN[1]) / RES) for v in (y0, y1))
    cells[iy0:iy1, ix0:ix1] = OCCUPIED
    return cells


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, -2.5])
def test_the_edge_ahead_is_the_first_occupied_cell_along_the_heading(yaw: float) -> None:
    """A bench whose near edge is 0.55 m ahead of the base, at any heading."""
    c, s = math.cos(yaw), math.sin(yaw)
    xy = (1.0 - 0.55 * c, 0.5 - 0.55 * s)  # the edge's middle at (1.0, 0.5)
    # the bench: 0.6 m deep beyond the edge, 1 m across, as a rotated set of points
    cells = np.zeros((200, 200), np.uint8)
    for a in np.arange(0.0, 0.6, RES / 2):
        for b in np.arange(-0.5, 0.5, RES / 2):
            x, y = 1.0 + c * a - s * b, 0.5 + s * a + c * b
            cells[int((y - ORIGIN[1]) // RES), int((x - ORIGIN[0]) // RES)] = OCCUPIED
    edge = support_ahead_m(cells, RES, ORIGIN, xy, yaw, 0.0)
    assert 0.55 - RES - 1e-9 <= edge <= 0.55 + RES / 2  # within the cell, never past it


def test_nothing_ahead_or_beside_the_corridor_is_no_edge() -> None:
    cells = grid_with(0.5, 1.0, 0.3, 1.0)  # ahead of the base but 0.3 m to its left
    assert support_ahead_m(cells, RES, ORIGIN, (0.0, 0.0), 0.0, 0.0) == math.inf
    assert support_ahead_m(np.zeros((200, 200), np.uint8), RES, ORIGIN, (0.0, 0.0), 0.0, 0.0) == (
        math.inf
    )
    # the corridor along a line 0.3 m to the left meets it
    assert 0.5 - RES - 1e-9 <= support_ahead_m(cells, RES, ORIGIN, (0.0, 0.0), 0.0, 0.3) <= 0.5


def test_a_box_off_a_bench_backs_the_base_off_so_the_stowed_box_clears_its_edge() -> None:
    """Hall seed 11's shift: box_1 side-grasped on bench_1 with the TCP at 0.94 m, the
    bench's end 0.545 m ahead of the base, the box 8 cm past the TCP."""
    ahead, _, _ = posture_tcp("stow")
    back = stow_back_off_m(0.939, 0.545, 0.08)
    assert back == pytest.approx(ahead + 0.08 + MARGIN_M - 0.545)
    assert 0.05 < back < 0.1
    # backed off so, the stowed box's far end stays the margin short of the edge
    assert ahead + 0.08 == pytest.approx(0.545 + back - MARGIN_M)


def test_no_back_off_where_the_stowed_object_stays_above_its_support_or_short_of_it() -> None:
    ahead, _, up = posture_tcp("stow")
    stow_z = STAND_BASE_HEIGHT_M + up
    assert stow_back_off_m(stow_z, 0.4, 0.03) == 0.0  # a bottle off a table: level with it
    assert stow_back_off_m(0.94, ahead + 0.08 + MARGIN_M, 0.08) == 0.0  # the edge far enough
    assert stow_back_off_m(0.94, math.inf, 0.08) == 0.0  # no edge ahead
    assert stow_back_off_m(1.2, 0.1, 0.11) == BACK_OFF_MAX_M  # never more than the bound
