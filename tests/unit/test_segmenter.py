"""The segmenter's runtime: instance separation, truth instances, metrics, and the shipped
network finding the bottle in a render of a world it never saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.perception import metrics
from services.perception.segmenter import (
    DEFAULT_MODEL,
    Instance,
    Segmenter,
    SegmenterError,
    TruthSegmenter,
    bbox_of,
    depth_cuts,
    split_instances,
)

UNSEEN_SEED = 20_001  # neither a training (0..) nor a validation (10000..) world


def _two_blocks(far_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A mask of two touching blocks, the left at 2 m, the right at `far_m`."""
    mask = np.zeros((40, 60), bool)
    mask[10:30, 10:50] = True
    depth = np.full(mask.shape, 6.0, np.float32)
    depth[:, :30], depth[:, 30:] = 2.0, far_m
    return mask, depth


def test_a_depth_step_splits_one_class_mask_into_two_instances() -> None:
    mask, depth = _two_blocks(3.0)
    parts = split_instances(mask, depth, depth_cuts(depth), min_area=10)
    assert len(parts) == 2
    left, right = sorted(parts, key=lambda p: np.nonzero(p)[1].min())
    assert bbox_of(left) == (10, 10, 30, 30) and bbox_of(right) == (30, 10, 50, 30)
    assert np.array_equal(left | right, mask)  # the cut pixels were given back


def test_a_smooth_surface_stays_one_instance() -> None:
    mask, depth = _two_blocks(2.02)
    assert len(split_instances(mask, depth, depth_cuts(depth), min_area=10)) == 1


def test_missing_depth_never_cuts() -> None:
    mask, depth = _two_blocks(0.0)
    assert not depth_cuts(depth).any()
    assert len(split_instances(mask, depth, depth_cuts(depth), min_area=10)) == 1


def test_truth_instances_keep_the_known_classes_only() -> None:
    labels = np.zeros((10, 10), np.int32)
    labels[1:3, 1:3], labels[5:9, 5:9], labels[0, 9] = 1, 2, 3
    names = {1: "bottle_1", 2: "person_2", 3: "table_1", 4: "can_1"}  # can_1 is not in view
    found = TruthSegmenter().segment(labels, names)
    assert [(i.class_name, i.truth_id, i.bbox) for i in found] == [
        ("bottle", "bottle_1", (1, 1, 3, 3)),
        ("person", "person_2", (5, 5, 9, 9)),
    ]


def _inst(cls: str, mask: np.ndarray) -> Instance:
    return Instance(cls, 1.0, mask, bbox_of(mask))


def test_matching_is_one_to_one_within_a_class() -> None:
    a, b = np.zeros((20, 20), bool), np.zeros((20, 20), bool)
    a[0:10, 0:10], b[0:10, 10:20] = True, True
    truth = [_inst("person", a), _inst("person", b)]
    blob = _inst("person", a | b)  # one blob over both people: counts for one only
    found = metrics.match_instances([blob], truth, ["person_1", "person_2"])
    assert sorted(m.iou for m in found) == [0.0, 0.5]
    bottle = _inst("bottle", a)  # another class never matches
    assert metrics.match_instances([bottle], truth[:1], ["person_1"])[0].iou == 0.0


def test_person_recall_counts_plainly_visible_people_only() -> None:
    def m(iou: float, pixels: int, depth: float) -> metrics.Match:
        return metrics.Match("person_1", "person", iou, pixels, depth, 0)

    matches = [m(0.9, 600, 3.0), m(0.2, 800, 5.0), m(0.0, 300, 2.0), m(0.0, 900, 9.0)]
    assert metrics.person_recall(matches) == (1, 2)


def test_bad_frames_are_refused_with_what_was_wrong() -> None:
    seg = Segmenter(DEFAULT_MODEL)
    with pytest.raises(SegmenterError, match="uint8"):
        seg.segment(np.zeros((240, 320, 3), np.float32), np.zeros((240, 320), np.float32))
    with pytest.raises(SegmenterError, match="does not match"):
        seg.segment(np.zeros((240, 320, 3), np.uint8), np.zeros((120, 160), np.float32))


def test_a_model_without_its_sidecar_is_refused(tmp_path: Path) -> None:
    model = tmp_path / "m.onnx"
    model.write_bytes(DEFAULT_MODEL.read_bytes())
    with pytest.raises(SegmenterError, match="sidecar"):
        Segmenter(model)


def test_the_shipped_network_finds_the_bottle_in_an_unseen_world() -> None:
    from services.sim import dataset

    names, frames = dataset.render_seed(UNSEEN_SEED)
    seg = Segmenter(DEFAULT_MODEL)
    truth_seg = TruthSegmenter()
    ious: list[float] = []
    for frame in frames[: dataset.WRIST_ARTIFACT_FRAMES]:  # close-ups from standoff poses
        depth = frame.depth_mm.astype(np.float32) * 1e-3
        truth = [t for t in truth_seg.segment(frame.labels, names) if t.class_name == "bottle"]
        truth = [t for t in truth if np.count_nonzero(t.mask) >= 300]
        found = metrics.match_instances(
            seg.segment(frame.rgb, depth), truth, [t.truth_id or "" for t in truth]
        )
        ious += [m.iou for m in found]
    assert ious, "no bottle close-up in this seed's wrist frames"
    assert min(ious) >= 0.6, ious
