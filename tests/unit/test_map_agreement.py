"""The map-agreement figure on synthetic grids: a map that saw a thick wall's face agrees
fully (its inside was never visible), a map a cell off still agrees, a phantom obstacle
and a missed pillar each lower it."""

from __future__ import annotations

import numpy as np

from bench.map_agreement import FREE, OCCUPIED, UNKNOWN, agreement


def hall() -> tuple[np.ndarray, np.ndarray]:
    truth = np.zeros((60, 80), bool)
    truth[:, :5] = True  # a wall 5 cells thick on the left
    truth[30:34, 40:44] = True  # a pillar
    cells = np.full(truth.shape, UNKNOWN, np.uint8)
    cells[:, 5:] = FREE
    cells[:, 5 - 1] = OCCUPIED  # the wall's face, as the lidar sees it
    cells[30:34, 40:44] = OCCUPIED
    cells[30:34, 41:43] = UNKNOWN  # the pillar's inside, never seen
    cells[31:33, 40] = OCCUPIED
    return cells, truth


def test_a_map_of_the_faces_agrees_fully() -> None:
    cells, truth = hall()
    a = agreement(cells, truth)
    assert a["iou_within_5cm"] > 0.97
    assert a["false_occupied_cells"] == 0


def test_a_cell_off_still_agrees_a_phantom_and_a_miss_do_not() -> None:
    cells, truth = hall()
    shifted = np.full_like(cells, UNKNOWN)
    shifted[:, 1:] = cells[:, :-1]  # everything a cell to the right
    assert agreement(shifted, truth)["iou_within_5cm"] > 0.95
    phantom = cells.copy()
    phantom[10:20, 60:70] = OCCUPIED
    assert agreement(phantom, truth)["false_occupied_cells"] == 100
    assert agreement(phantom, truth)["iou_within_5cm"] < 0.8
    missed = cells.copy()
    missed[30:34, 40:44] = FREE
    a = agreement(missed, truth)
    assert a["truth_seen_missed_cells"] > 0
    assert a["iou_within_5cm"] < agreement(cells, truth)["iou_within_5cm"]
