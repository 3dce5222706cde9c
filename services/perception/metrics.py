"""How good a segmentation is against truth: matched mask IoU and person recall.

Truth instances come from `TruthSegmenter` (they carry `truth_id`). `match_instances`
pairs each truth instance with at most one predicted instance of its class, greedily by
IoU (highest first), so one blob covering two people counts for one of them only; an
unmatched truth instance has IoU 0. A person counts as found when matched with IoU ≥ 0.5
(`person_recall`), over the people that are plainly visible: at least `min_pixels` truth
pixels, their median depth within `max_depth_m`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

#: A truth person counts as found when matched at this IoU or better.
RECALL_IOU = 0.5


class Masked(Protocol):
    """What is matched: a class and a full-frame mask (a segmenter `Instance`)."""

    @property
    def class_name(self) -> str: ...
    @property
    def mask(self) -> NDArray[np.bool_]: ...


class Match(NamedTuple):
    """A truth instance and how well it was segmented."""

    truth_id: str
    class_name: str
    iou: float  # 0 when unmatched
    pixels: int  # truth pixels
    depth_m: float  # median depth of the truth pixels (0 when none has depth)
    matched: int | None  # index of the predicted instance, or None


def mask_iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Intersection over union of two masks of the same shape (0 when both are empty)."""
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b)) / union if union else 0.0


def match_instances(
    predicted: Sequence[Masked],
    truth: Sequence[Masked],
    truth_ids: Sequence[str],
    depth: NDArray[np.floating] | None = None,
) -> list[Match]:
    """One `Match` per truth instance (same order), one-to-one within each class."""
    if len(truth_ids) != len(truth):
        raise ValueError(f"{len(truth_ids)} truth ids for {len(truth)} truth instances")
    pairs: list[tuple[float, int, int]] = []
    for t, tru in enumerate(truth):
        for p, pred in enumerate(predicted):
            if pred.class_name == tru.class_name:
                iou = mask_iou(pred.mask, tru.mask)
                if iou > 0.0:
                    pairs.append((iou, t, p))
    best: dict[int, tuple[float, int]] = {}
    used: set[int] = set()
    for iou, t, p in sorted(pairs, reverse=True):
        if t not in best and p not in used:
            best[t] = (iou, p)
            used.add(p)
    out: list[Match] = []
    for t, tru in enumerate(truth):
        pixels = int(np.count_nonzero(tru.mask))
        d = 0.0
        if depth is not None:
            values = np.asarray(depth)[tru.mask]
            values = values[values > 0]
            d = float(np.median(values)) if values.size else 0.0
        iou, p = best.get(t, (0.0, -1))
        out.append(Match(truth_ids[t], tru.class_name, iou, pixels, d, p if p >= 0 else None))
    return out


def person_recall(
    matches: Sequence[Match], min_pixels: int = 500, max_depth_m: float = 8.0
) -> tuple[int, int]:
    """(found, counted) over truth people with ≥ min_pixels within max_depth_m."""
    counted = [
        m
        for m in matches
        if m.class_name == "person" and m.pixels >= min_pixels and 0.0 < m.depth_m <= max_depth_m
    ]
    return sum(m.iou >= RECALL_IOU for m in counted), len(counted)


def mean_iou(matches: Sequence[Match], class_name: str, min_pixels: int = 0) -> float | None:
    """Mean matched IoU of a class's truth instances with ≥ min_pixels (None when none)."""
    ious = [m.iou for m in matches if m.class_name == class_name and m.pixels >= min_pixels]
    return float(np.mean(ious)) if ious else None
