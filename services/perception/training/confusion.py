"""A segmenter's per-class confusion by range: what each truth instance was read as, and
what its false instances lie on.

`Confusion.add(predicted, labels, names, depth)` takes one frame: the runtime `Segmenter`'s
instances, the sim's instance labels with their truth ids (`bottle_1`, `table_2`,
`robot`) and the frame's true depth (m, 0 = none). The truth instances are
`TruthSegmenter`'s (`TRUE_CLASSES`). Each is paired with at most one predicted instance of
any class, greedily by mask IoU (highest first), at IoU ≥ `MATCH_IOU` only (the IoU at
which `metrics.person_recall` counts a person found): the pair's predicted class is where
the truth instance is counted, no pair is `missed`. A truth instance counts when it has
at least `min_pixels` pixels (people `min_person_pixels`, as `metrics.person_recall`
counts them); smaller ones are matched all the same (a prediction paired with one is not
false) but not counted. Its range is the median true depth of its pixels. Those cut by the
image's border are counted, and also apart (`cut`: read right, of how many): a bottle
whose neck is out of the frame is a can to look at.

A predicted instance paired with no truth instance is false. Its range is the median true
depth under its mask, and it is filed by the truth it lies on (`UNDER`): an `object` when
at least `OBJECT_SHARE` of its pixels lie on bottles, cans, boxes or people (a fragment or
a double of one, or one that bled far beyond it), else what most of its pixels lie on: a
`table`, `bench`, `pallet` or other furniture (`rack/machine`), the `background` (floor,
walls, nothing) or the `robot` itself. Ranges are `BINS` (m, [lower, upper)); an
instance outside them or without depth is counted in `beyond` only. Pure numpy: no
simulator, no network here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from services.perception.metrics import RECALL_IOU, Masked, mask_iou
from services.perception.segmenter import TruthSegmenter

TRUE_CLASSES = ("bottle", "can", "box", "person")
MISSED = "missed"
#: Range bins (m): the lower bound is in, the upper one out.
BINS: tuple[tuple[float, float], ...] = ((0.0, 1.5), (1.5, 3.0), (3.0, 5.0))
#: A truth instance and a predicted one pair at this IoU or better.
MATCH_IOU = RECALL_IOU
#: What a false instance lies on (the truth under most of its pixels).
UNDER = ("object", "table", "bench", "pallet", "rack/machine", "background", "robot")
#: A false instance this much on truth objects is filed under `object`.
OBJECT_SHARE = 1 / 3
_FURNITURE = {"table": "table", "bench": "bench", "pallet": "pallet"}
_FURNITURE |= {"rack": "rack/machine", "machine": "rack/machine"}


def bin_name(lo: float, hi: float) -> str:
    """`1.5-3 m`."""
    return f"{lo:g}-{hi:g} m"


def bin_of(depth_m: float, bins: Sequence[tuple[float, float]] = BINS) -> str | None:
    """The name of the bin `depth_m` falls in, or None (outside them all, or no depth)."""
    for lo, hi in bins:
        if lo <= depth_m < hi and depth_m > 0.0:
            return bin_name(lo, hi)
    return None


def under_of(truth_id: str) -> str:
    """What a truth id is, as `UNDER` files it: `table_2` → `table`, `wall_1` → `background`."""
    if truth_id == "robot":
        return "robot"
    prefix = truth_id.rsplit("_", 1)[0]
    if prefix in TRUE_CLASSES:
        return "object"
    return _FURNITURE.get(prefix, "background")


def pair_any_class(
    predicted: Sequence[Masked], truth: Sequence[Masked], min_iou: float = MATCH_IOU
) -> list[int | None]:
    """Per truth instance, the index of the predicted instance it pairs with (any class,
    greedily by IoU, one to one, at IoU ≥ `min_iou`), or None."""
    pairs: list[tuple[float, int, int]] = []
    for t, tru in enumerate(truth):
        for p, pred in enumerate(predicted):
            iou = mask_iou(pred.mask, tru.mask)
            if iou >= min_iou:
                pairs.append((iou, t, p))
    best: dict[int, int] = {}
    used: set[int] = set()
    for _, t, p in sorted(pairs, key=lambda e: (-e[0], e[1], e[2])):  # ties: lower indices
        if t not in best and p not in used:
            best[t] = p
            used.add(p)
    return [best.get(t) for t in range(len(truth))]


def _median_depth(depth: NDArray[np.floating], mask: NDArray[np.bool_]) -> float:
    values = depth[mask]
    values = values[values > 0]
    return float(np.median(values)) if values.size else 0.0


def truth_under(
    mask: NDArray[np.bool_], labels: NDArray[np.integer], names: Mapping[int, str]
) -> str:
    """What a false instance's `mask` lies on: `object` when `OBJECT_SHARE` of its pixels
    are on objects, else `under_of` the label most of them carry (unlabelled: background)."""
    counts = np.bincount(labels[mask].ravel().astype(np.int64))
    if not counts.size:
        return "background"
    kinds = [under_of(names.get(label, "")) for label in range(counts.size)]
    on_objects = sum(int(n) for n, kind in zip(counts, kinds, strict=True) if kind == "object")
    if on_objects >= OBJECT_SHARE * counts.sum():
        return "object"
    return kinds[int(np.argmax(counts))]


@dataclass
class Confusion:
    """Counts over frames (see the module docstring). `table[bin][true][read as]`,
    `false[bin][read as][under]`; `cut[bin][true]`: [read right, counted] of the truth
    instances cut by the image's border; `beyond`: truth and false instances outside the
    bins; `small`: truth instances too small to count."""

    min_pixels: int = 50
    min_person_pixels: int = 500
    bins: tuple[tuple[float, float], ...] = BINS
    classes: tuple[str, ...] = TRUE_CLASSES
    frames: int = 0
    table: dict[str, dict[str, dict[str, int]]] = field(default_factory=dict)
    false: dict[str, dict[str, dict[str, int]]] = field(default_factory=dict)
    cut: dict[str, dict[str, list[int]]] = field(default_factory=dict)
    beyond: dict[str, int] = field(default_factory=lambda: {"truth": 0, "false": 0})
    small: int = 0

    def __post_init__(self) -> None:
        columns = (*self.classes, MISSED)
        for lo, hi in self.bins:
            name = bin_name(lo, hi)
            self.table.setdefault(name, {c: dict.fromkeys(columns, 0) for c in self.classes})
            self.false.setdefault(name, {c: dict.fromkeys(UNDER, 0) for c in self.classes})
            self.cut.setdefault(name, {c: [0, 0] for c in self.classes})

    def add(
        self,
        predicted: Sequence[Masked],
        labels: NDArray[np.integer],
        names: Mapping[int, str],
        depth: NDArray[np.floating],
    ) -> None:
        """Count one frame: `predicted` instances against the truth of `labels` (H, W) with
        `names` (label → truth id), ranged by the true `depth` (H, W, m)."""
        labels, depth = np.asarray(labels), np.asarray(depth)
        truth = TruthSegmenter(self.classes).segment(labels, dict(names))
        paired = pair_any_class(predicted, truth)
        self.frames += 1
        for tru, p in zip(truth, paired, strict=True):
            floor = self.min_person_pixels if tru.class_name == "person" else self.min_pixels
            if np.count_nonzero(tru.mask) < floor:
                self.small += 1
                continue
            where = bin_of(_median_depth(depth, tru.mask), self.bins)
            if where is None:
                self.beyond["truth"] += 1
                continue
            read = MISSED if p is None else predicted[p].class_name
            row = self.table[where][tru.class_name]
            row[read] = row.get(read, 0) + 1
            u0, v0, u1, v1 = tru.bbox
            if min(u0, v0) == 0 or u1 == labels.shape[1] or v1 == labels.shape[0]:
                self.cut[where][tru.class_name][0] += read == tru.class_name
                self.cut[where][tru.class_name][1] += 1
        taken = {p for p in paired if p is not None}
        for p, pred in enumerate(predicted):
            if p in taken:
                continue
            where = bin_of(_median_depth(depth, pred.mask), self.bins)
            if where is None:
                self.beyond["false"] += 1
                continue
            row = self.false[where].setdefault(pred.class_name, dict.fromkeys(UNDER, 0))
            row[truth_under(pred.mask, labels, names)] += 1

    def to_dict(self) -> dict[str, Any]:
        """The counts as JSON-ready values, with each bin's per-class share read right."""
        correct = {
            name: {
                c: round(row[c] / n, 3) if (n := sum(row.values())) else None
                for c, row in rows.items()
            }
            for name, rows in self.table.items()
        }
        return {
            "frames": self.frames,
            "bins_m": [list(b) for b in self.bins],
            "match_iou": MATCH_IOU,
            "min_pixels": {"object": self.min_pixels, "person": self.min_person_pixels},
            "confusion": self.table,
            "correct": correct,
            "false": self.false,
            "cut": self.cut,
            "false_total": {
                name: sum(sum(r.values()) for r in rows.values())
                for name, rows in self.false.items()
            },
            "beyond": self.beyond,
            "small": self.small,
        }


def markdown(report: Mapping[str, Any]) -> str:
    """`Confusion.to_dict()` as markdown: per bin, the confusion table (rows: true class;
    columns: read as, missed, how many, the share read right, and read right of those cut
    by the border) and the false instances (rows: read as; columns: what they lie on)."""
    out: list[str] = []
    for name, rows in report["confusion"].items():
        columns = list(next(iter(rows.values())))
        out += [f"**{name}**", ""]
        out.append("| true \\ read as | " + " | ".join(columns) + " | n | right | cut: right |")
        out.append("|---" * (len(columns) + 4) + "|")
        for cls, row in rows.items():
            n = sum(row.values())
            share = report["correct"][name][cls]
            right = "–" if share is None else f"{share:.2f}"
            cells = " | ".join(str(row[c]) for c in columns)
            cut_right, cut_n = report["cut"][name][cls]
            out.append(f"| {cls} | {cells} | {n} | {right} | {cut_right}/{cut_n} |")
        false = report["false"][name]
        out += ["", "| false, read as | " + " | ".join(UNDER) + " | all |"]
        out.append("|---" * (len(UNDER) + 2) + "|")
        for cls, row in false.items():
            cells = " | ".join(str(row[u]) for u in UNDER)
            out.append(f"| {cls} | {cells} | {sum(row.values())} |")
        out.append("")
    return "\n".join(out)
