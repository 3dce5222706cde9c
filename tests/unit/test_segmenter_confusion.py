"""The segmenter's confusion report on hand-made label images: pairing across classes,
range bins from the truth's median depth, false instances filed by what lies under them."""

from __future__ import annotations

import numpy as np
import pytest

from services.perception.segmenter import Instance, bbox_of
from services.perception.training import confusion
from services.perception.training.confusion import Confusion, bin_of, pair_any_class

H, W = 60, 80
NAMES = {1: "can_1", 2: "bottle_1", 3: "pallet_1", 4: "table_1", 5: "robot", 6: "person_1"}


def _box(v0: int, v1: int, u0: int, u1: int) -> np.ndarray:
    mask = np.zeros((H, W), dtype=bool)
    mask[v0:v1, u0:u1] = True
    return mask


def _pred(cls: str, mask: np.ndarray) -> Instance:
    return Instance(cls, 0.9, mask, bbox_of(mask))


def _scene(depth_m: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A can (10 x 10 px) and a bottle (10 x 10) at `depth_m`, a pallet and a table
    behind at 4 m, the robot's own arm at 0.4 m in a corner."""
    labels = np.zeros((H, W), dtype=np.uint16)
    depth = np.full((H, W), 6.0, dtype=np.float32)
    for label, (v0, v1, u0, u1), d in (
        (3, (40, 60, 0, 40), 4.0),
        (4, (40, 60, 40, 80), 4.0),
        (5, (0, 10, 70, 80), 0.4),
        (1, (10, 20, 10, 20), depth_m),
        (2, (10, 20, 40, 50), depth_m),
    ):
        labels[v0:v1, u0:u1] = label
        depth[v0:v1, u0:u1] = d
    return labels, depth


def test_a_can_read_as_a_box_counts_in_the_box_column_of_its_range() -> None:
    labels, depth = _scene(2.0)
    counts = Confusion()
    counts.add([_pred("box", labels == 1), _pred("bottle", labels == 2)], labels, NAMES, depth)
    rows = counts.table["1.5-3 m"]
    assert rows["can"] == {"bottle": 0, "can": 0, "box": 1, "person": 0, "missed": 0}
    assert rows["bottle"]["bottle"] == 1
    assert sum(sum(r.values()) for r in counts.false["1.5-3 m"].values()) == 0
    assert counts.to_dict()["correct"]["1.5-3 m"]["can"] == 0.0


def test_a_mask_overlapping_under_half_leaves_the_truth_missed_and_is_false() -> None:
    labels, depth = _scene(1.0)
    half = (labels == 1) & (np.arange(W) < 14)[None, :]  # 4 of the can's 10 columns
    counts = Confusion(min_pixels=50)
    counts.add([_pred("can", half)], labels, NAMES, depth)
    assert counts.table["0-1.5 m"]["can"]["missed"] == 1
    assert counts.false["0-1.5 m"]["can"]["object"] == 1


def test_false_instances_are_filed_by_what_lies_under_them() -> None:
    labels, depth = _scene(2.0)
    on_pallet = _box(44, 56, 5, 30)
    on_table_edge = _box(39, 43, 45, 75)  # one row of floor above three of the table
    on_robot = labels == 5
    on_floor = _box(25, 35, 20, 60)
    double = (labels == 2) & (np.arange(W) >= 46)[None, :]  # a can on most of the bottle
    predicted = [
        _pred("bottle", labels == 2),
        _pred("box", on_pallet),
        _pred("box", on_table_edge),
        _pred("person", on_robot),
        _pred("person", on_floor),
        _pred("can", double),
    ]
    counts = Confusion()
    counts.add(predicted, labels, NAMES, depth)
    far = counts.false["3-5 m"]
    assert far["box"]["pallet"] == 1 and far["box"]["table"] == 1
    assert counts.false["0-1.5 m"]["person"]["robot"] == 1
    assert counts.false["1.5-3 m"]["can"]["object"] == 1
    assert counts.beyond["false"] == 1  # the floor, 6 m away
    assert counts.table["1.5-3 m"]["bottle"]["bottle"] == 1


def test_ranges_are_the_truth_instances_median_depth() -> None:
    assert bin_of(0.3) == "0-1.5 m"
    assert bin_of(1.5) == "1.5-3 m"
    assert bin_of(2.999) == "1.5-3 m"
    assert bin_of(5.0) is None
    assert bin_of(0.0) is None
    labels, depth = _scene(2.0)
    depth[10:13, 10:20] = 0.9  # 30 of the can's 100 pixels nearer: the median stays at 2 m
    depth[13:14, 10:20] = 0.0  # no return: not counted in the median
    counts = Confusion()
    counts.add([], labels, NAMES, depth)
    assert counts.table["1.5-3 m"]["can"]["missed"] == 1
    labels, depth = _scene(5.5)
    counts.add([], labels, NAMES, depth)
    assert counts.beyond["truth"] == 2


def test_a_small_truth_instance_is_not_counted_and_its_match_is_not_false() -> None:
    labels, depth = _scene(2.0)
    counts = Confusion(min_pixels=150)
    counts.add([_pred("can", labels == 1)], labels, NAMES, depth)
    assert counts.small == 2
    assert sum(sum(r.values()) for r in counts.table["1.5-3 m"].values()) == 0
    assert sum(sum(r.values()) for r in counts.false["1.5-3 m"].values()) == 0


def test_a_person_counts_from_the_person_pixel_floor() -> None:
    labels, depth = _scene(2.0)
    labels[20:40, 60:70] = 6  # 200 pixels: under the 500 a person needs
    depth[20:40, 60:70] = 3.5
    counts = Confusion()
    counts.add([_pred("person", labels == 6)], labels, NAMES, depth)
    assert counts.small == 1
    counts = Confusion(min_person_pixels=100)
    counts.add([_pred("person", labels == 6)], labels, NAMES, depth)
    assert counts.table["3-5 m"]["person"]["person"] == 1


def test_pairing_is_one_to_one_by_highest_iou_across_classes() -> None:
    labels, _ = _scene()
    can, bottle = labels == 1, labels == 2
    truth = [_pred("can", can), _pred("bottle", bottle)]
    wide = can | _box(10, 20, 20, 24)  # IoU 100/140 with the can
    predicted = [_pred("bottle", wide), _pred("box", can), _pred("bottle", bottle)]
    assert pair_any_class(predicted, truth) == [1, 2]
    assert pair_any_class(predicted[:1], truth) == [0, None]
    assert pair_any_class(predicted[:1], truth, min_iou=0.8) == [None, None]


def test_the_report_reads_as_markdown_tables_per_range() -> None:
    labels, depth = _scene(2.0)
    counts = Confusion()
    counts.add([_pred("box", labels == 1)], labels, NAMES, depth)
    text = confusion.markdown(counts.to_dict())
    header = "| true \\ read as | bottle | can | box | person | missed | n | right | cut: right |"
    assert text.count(header) == 3
    assert "| can | 0 | 0 | 1 | 0 | 0 | 1 | 0.00 | 0/0 |" in text
    assert "| bottle | 0 | 0 | 0 | 0 | 1 | 1 | 0.00 | 0/0 |" in text


def test_instances_cut_by_the_border_are_also_counted_apart() -> None:
    labels, depth = _scene(2.0)
    labels[0:10, 30:36] = 7  # a bottle's lower body below the top border: 60 pixels
    depth[0:10, 30:36] = 1.0
    names = {**NAMES, 7: "bottle_2b"}
    counts = Confusion()
    counts.add([_pred("can", labels == 7), _pred("bottle", labels == 2)], labels, names, depth)
    assert counts.table["0-1.5 m"]["bottle"]["can"] == 1
    assert counts.cut["0-1.5 m"]["bottle"] == [0, 1]
    assert counts.cut["1.5-3 m"]["bottle"] == [0, 0]  # the whole one is not cut


@pytest.mark.parametrize(
    ("truth_id", "under"),
    [("table_3", "table"), ("rack_1", "rack/machine"), ("wall_2", "background"), ("", "background"),
     ("robot", "robot"), ("box_4", "object")],
)  # fmt: skip
def test_truth_ids_file_as_their_kind(truth_id: str, under: str) -> None:
    assert confusion.under_of(truth_id) == under
