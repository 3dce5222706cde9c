"""`common.grid.occupied_near`: which points lie in or by an occupied cell."""

from __future__ import annotations

import numpy as np

from common.grid import occupied_near


def test_points_in_beside_and_away_from_an_obstacle() -> None:
    occ = np.zeros((20, 20), bool)
    occ[5:10, 5:10] = True  # x, y 0.5–1.0 with 0.1 m cells at the origin
    pts = [(0.7, 0.7), (0.45, 0.7), (1.08, 0.7), (1.3, 0.7), (0.7, 1.2)]
    near = occupied_near(occ, 0.1, (0.0, 0.0), pts, 0.1)
    assert near.tolist() == [True, True, True, False, False]


def test_off_grid_and_non_finite_points_are_near_nothing() -> None:
    occ = np.ones((4, 4), bool)
    pts = [(-1.0, 0.1), (0.1, 9.0), (float("nan"), 0.1)]
    assert not occupied_near(occ, 0.1, (0.0, 0.0), pts, 0.2).any()


def test_a_zero_margin_counts_only_the_points_own_cell() -> None:
    occ = np.zeros((4, 4), bool)
    occ[1, 1] = True
    assert occupied_near(occ, 1.0, (0.0, 0.0), [(1.5, 1.5), (0.9, 1.5)], 0.0).tolist() == [
        True,
        False,
    ]
