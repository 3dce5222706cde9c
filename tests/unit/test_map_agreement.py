"""The map-agreement figure on synthetic grids: a map that saw a thick wall's face agrees
fully (its inside was never visible), a map a cell off still agrees, a phantom obstacle
and a missed pillar each lower it."""

from __future__ import annotations

import numpy as np

from bench.map_agreement import FREE, OCCUPIED, UNKNOWN, Alignment, agreement, align_to_truth


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


def test_a_map_turned_and_shifted_in_its_own_frame_is_aligned_back() -> None:
    """A room 6 x 4 m whose map came out turned 1.5° and shifted 14 cm (its frame anchored
    on a heading a little off): a poor IoU as it lies, a full one once aligned, and the
    alignment found undoes the motion."""
    res, origin = 0.05, (-4.0, -3.0)
    truth = np.zeros((120, 160), bool)
    truth[10:12, 20:140] = truth[108:110, 20:140] = True  # two long walls
    truth[10:110, 20:22] = truth[10:110, 138:140] = True  # two short ones
    truth[50:60, 70:80] = True  # a machine
    cells = np.where(truth, OCCUPIED, UNKNOWN).astype(np.uint8)
    cells[12:108, 22:138] = FREE
    cells[50:60, 70:80] = OCCUPIED
    moved = Alignment(np.radians(1.5), (0.12, -0.08), (0.0, 0.0)).warp(cells, res, origin)
    as_lies = agreement(moved, truth)["iou_within_5cm"]
    a = align_to_truth(moved, truth, res, origin)
    back = agreement(a.warp(moved, res, origin), truth)["iou_within_5cm"]
    assert as_lies < 0.7 and back > 0.95, (as_lies, back)
    assert abs(np.degrees(a.yaw_rad) + 1.5) < 0.1
    # the point the map put at the room's corner goes back there
    corner = Alignment(np.radians(1.5), (0.12, -0.08), (0.0, 0.0)).apply(np.array([[3.0, 2.0]]))
    assert np.allclose(a.apply(corner), [[3.0, 2.0]], atol=0.05)


def test_an_aligned_map_never_agrees_less_than_as_it_lies() -> None:
    """A map bent, not turned (its halves a few cells apart, as a SLAM map's error lies):
    the alignment is judged by the figure it reports, and doing nothing is a candidate,
    so "aligned" is never below "as it lies" (a hall map read 0.754, aligned 0.618)."""
    res, origin = 0.05, (-4.0, -3.0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        truth = np.zeros((120, 160), bool)
        truth[10:12, 20:140] = truth[108:110, 20:140] = True
        truth[10:110, 20:22] = truth[10:110, 138:140] = True
        for _k in range(6):
            y, x = rng.integers(20, 100), rng.integers(30, 130)
            truth[y : y + rng.integers(2, 8), x : x + rng.integers(2, 8)] = True
        cells = np.where(truth, OCCUPIED, FREE).astype(np.uint8)
        cells[:10], cells[110:], cells[:, :20], cells[:, 140:] = UNKNOWN, UNKNOWN, UNKNOWN, UNKNOWN
        bent = cells.copy()
        bent[:, 80:] = np.roll(cells[:, 80:], 2, axis=0)
        bent[60:, :] = np.roll(bent[60:, :], -2, axis=1)
        as_lies = agreement(bent, truth)["iou_within_5cm"]
        a = align_to_truth(bent, truth, res, origin)
        assert agreement(a.warp(bent, res, origin), truth)["iou_within_5cm"] >= as_lies
