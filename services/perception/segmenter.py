"""Instance segmentation at run time: the shipped ONNX network through onnxruntime.

`Segmenter(model).segment(rgb, depth)` → `Instance`s (class, score, full-frame mask, box).
The network (`services.perception.training.model`) labels every pixel with a class; the
instances are the connected components of each class's mask after cutting it along depth
discontinuities (two people one behind the other, two cans side by side at different
depths), the cut pixels given back to the neighbour nearest in depth. The artifact classes
(bottle, can, box) are pooled before the split and each component takes the class its
pixels' probabilities vote for, so an object read partly as one class and partly as another
stays whole; people are split on their own. A component's score is its class's mean
probability over it; components under `min_area` pixels (`min_person_area` for people) or
`min_score` are dropped. The
model's JSON sidecar (same name, `.json`) gives the classes, input size and normalisation;
frames of another size are resized in and the masks resized back.

`TruthSegmenter` turns the sim's `segmentation_truth` labels into the same `Instance`s: for
ablation and evaluation only (`--segmenter truth`), never for the robot's own perception.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from services.perception.onnx_net import OnnxError, OnnxNet

BoolArray = NDArray[np.bool_]
#: The model the repository ships.
DEFAULT_MODEL = Path(__file__).resolve().parent / "models" / "segmenter.onnx"
#: A depth step between neighbours larger than this (m) plus `DEPTH_JUMP_REL` × depth cuts:
#: more than a body's own relief (a torso stands ~9 cm in front of the legs), less than the
#: gap between two objects one behind the other.
DEPTH_JUMP_M = 0.10
DEPTH_JUMP_REL = 0.03


@dataclass(frozen=True)
class Instance:
    """One segmented instance.

    class_name: bottle, can, box, person, …; score: [0, 1]; mask: (H, W) bool, full frame;
    bbox: (u0, v0, u1, v1) pixels, inclusive-exclusive; truth_id: the sim's id (truth only).
    """

    class_name: str
    score: float
    mask: BoolArray
    bbox: tuple[int, int, int, int]
    truth_id: str | None = None


class SegmenterError(ValueError):
    """A model that cannot be used, or a frame that cannot be segmented; says which and why."""


def _softmax(logits: NDArray[np.float32]) -> NDArray[np.float32]:
    """Class probabilities along axis 0."""
    e = np.exp(logits - logits.max(axis=0, keepdims=True))
    return np.asarray(e / e.sum(axis=0, keepdims=True), dtype=np.float32)


def _argmax0(x: NDArray[np.float32]) -> NDArray[np.uint8]:
    """`x.argmax(axis=0)` of finite (C, h, w) scores as uint8, plane by plane: the first
    maximum wins, as in argmax, at a tenth of its cost (contiguous planes, no stride C)."""
    best = x[0].copy()
    out = np.zeros(best.shape, dtype=np.uint8)
    for c in range(1, len(x)):
        out[x[c] > best] = c
        np.maximum(best, x[c], out=best)
    return out


def bbox_of(mask: BoolArray) -> tuple[int, int, int, int]:
    """(u0, v0, u1, v1) of a non-empty mask, inclusive-exclusive."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def depth_cuts(depth: NDArray[np.floating]) -> BoolArray:
    """Pixels on the far side of a depth discontinuity with a 4-neighbour (no-return is 0
    and never cuts)."""
    d = np.asarray(depth, dtype=np.float32)
    cut = np.zeros(d.shape, dtype=bool)
    returned = d > 0
    for axis in (0, 1):
        a = d[:-1, :] if axis == 0 else d[:, :-1]
        b = d[1:, :] if axis == 0 else d[:, 1:]
        ra = returned[:-1, :] if axis == 0 else returned[:, :-1]
        rb = returned[1:, :] if axis == 0 else returned[:, 1:]
        step = a - b  # > 0 exactly where a > b (IEEE subtraction of finite floats)
        jump = np.abs(step) > DEPTH_JUMP_M + DEPTH_JUMP_REL * np.minimum(a, b)
        jump &= ra
        jump &= rb
        far_a, far_b = jump & (step > 0), jump & (step < 0)
        if axis == 0:
            cut[:-1, :] |= far_a
            cut[1:, :] |= far_b
        else:
            cut[:, :-1] |= far_a
            cut[:, 1:] |= far_b
    return cut


def depth_cuts_within(depth: NDArray[np.floating], box: tuple[int, int, int, int]) -> BoolArray:
    """`depth_cuts(depth)` inside `box` (u0, v0, u1, v1), False outside it. A pixel's cut
    reads its 4-neighbours alone: the box grown by one pixel is all that is computed."""
    h, w = depth.shape
    u0, v0, u1, v1 = box
    a0, b0 = max(u0 - 1, 0), max(v0 - 1, 0)
    cut = np.zeros((h, w), dtype=bool)
    grown = depth_cuts(depth[b0 : min(v1 + 1, h), a0 : min(u1 + 1, w)])
    cut[v0:v1, u0:u1] = grown[v0 - b0 : v1 - b0, u0 - a0 : u1 - a0]
    return cut


def split_instances(
    mask: BoolArray, depth: NDArray[np.floating], cuts: BoolArray, min_area: int
) -> list[BoolArray]:
    """The components of `mask` separated by `cuts`, cut pixels returned to the
    4-neighbour component nearest in depth; components under `min_area` dropped.
    Computed on the mask's bounding box: nothing outside it is a component."""
    if not mask.any():
        return []
    u0, v0, u1, v1 = bbox_of(mask)
    box = np.s_[v0:v1, u0:u1]
    parts = []
    for inside in _split(mask[box], np.asarray(depth, dtype=np.float32)[box], cuts[box], min_area):
        part = np.zeros(mask.shape, dtype=bool)
        part[box] = inside
        parts.append(part)
    return parts


def _split(
    mask: BoolArray, d: NDArray[np.float32], cuts: BoolArray, min_area: int
) -> list[BoolArray]:
    """`split_instances` of a mask's box: a neighbour off the box is off the mask, as one
    clipped to the box (the pixel itself, a cut one) is."""
    inner = (mask & ~cuts).astype(np.uint8)
    n, labels = cv2.connectedComponents(inner, connectivity=4)
    if n <= 1:
        return []
    rest = mask & cuts
    if rest.any():
        vs, us = np.nonzero(rest)
        h, w = mask.shape
        best = np.full(vs.size, np.inf, dtype=np.float32)
        owner = np.zeros(vs.size, dtype=labels.dtype)
        d_rest = d[vs, us]
        for dv, du in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            nv, nu = np.clip(vs + dv, 0, h - 1), np.clip(us + du, 0, w - 1)
            lab = labels[nv, nu]
            gap = np.where(lab > 0, np.abs(d[nv, nu] - d_rest), np.inf)
            better = gap < best
            best[better], owner[better] = gap[better], lab[better]
        labels[vs, us] = owner
    areas = np.bincount(labels.ravel(), minlength=n)
    return [labels == k for k in range(1, n) if areas[k] >= min_area]


class Segmenter:
    """The ONNX network (`OnnxNet`) plus instance separation (see the module)."""

    def __init__(
        self,
        model: Path | str = DEFAULT_MODEL,
        min_area: int = 25,
        min_person_area: int = 150,
        min_score: float = 0.3,
        threads: int | None = None,
    ) -> None:
        model = Path(model)
        meta_path = model.with_suffix(".json")
        try:
            self.meta: dict[str, Any] = json.loads(meta_path.read_text())
            self.classes: tuple[str, ...] = tuple(self.meta["classes"])
            self.width, self.height = (int(v) for v in self.meta["input_size"])
            self.mean = np.asarray(self.meta["mean"], dtype=np.float32)
            self.std = np.asarray(self.meta["std"], dtype=np.float32)
            self.inv_depth_max = float(self.meta["inv_depth_max"])
        except (OSError, KeyError, TypeError, ValueError) as exc:
            raise SegmenterError(f"model sidecar {meta_path} unusable: {exc}") from exc
        try:
            self.net = OnnxNet(model, threads)
        except OnnxError as exc:
            raise SegmenterError(str(exc)) from exc
        self.min_area, self.min_score = min_area, min_score
        # People apart; the artifact classes pooled, so that one object read partly as a can
        # and partly as a bottle stays one instance (of the class most of it voted for).
        # Person fragments smaller than a far person's legs are noise, not people.
        objects = [c for c, name in enumerate(self.classes) if name not in ("background", "person")]
        people = [c for c, name in enumerate(self.classes) if name == "person"]
        self.groups = [
            (group, area)
            for group, area in ((objects, min_area), (people, max(min_area, min_person_area)))
            if group
        ]

    def blob(self, rgb: NDArray[np.uint8], depth: NDArray[np.floating]) -> NDArray[np.float32]:
        """The network's (1, 4, h, w) input for one frame (resized to the model's size)."""
        return self._blob(*self._check(rgb, depth))

    def _blob(self, image: NDArray[np.uint8], d: NDArray[np.float32]) -> NDArray[np.float32]:
        """`blob` of checked arrays, each channel written in place in float32."""
        size = (self.width, self.height)
        if image.shape[:2] != (self.height, self.width):
            image = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA))
            d = np.asarray(cv2.resize(d, size, interpolation=cv2.INTER_NEAREST))
        out = np.empty((1, 4, self.height, self.width), dtype=np.float32)
        for c, channel in enumerate(cv2.split(image)):
            x = out[0, c]
            np.multiply(channel, np.float32(1 / 255), out=x, dtype=np.float32)
            x -= self.mean[c]
            x /= self.std[c]
        inv = out[0, 3]
        np.maximum(d, np.float32(1e-3), out=inv)
        np.divide(np.float32(1.0), inv, out=inv)
        inv[~(d > 0)] = 0.0
        np.minimum(inv, np.float32(self.inv_depth_max), out=inv)
        inv *= np.float32(1.0 / self.inv_depth_max)
        return out

    def forward(self, blob: NDArray[np.float32]) -> NDArray[np.float32]:
        """Raw class logits (C, h, w) of one input blob: the network's part."""
        try:
            out = self.net.run(blob)[0]
        except OnnxError as exc:
            raise SegmenterError(str(exc)) from exc
        if out.ndim != 4 or out.shape[1] != len(self.classes):
            raise SegmenterError(f"model output {out.shape} is not (1, {len(self.classes)}, h, w)")
        return out[0]

    def segment(self, rgb: NDArray[np.uint8], depth: NDArray[np.floating]) -> list[Instance]:
        """Instances in an (H, W, 3) uint8 RGB frame with its (H, W) depth in m (0 = none)."""
        rgb, depth = self._check(rgb, depth)
        logits = self.forward(self._blob(rgb, depth))
        h, w = depth.shape
        if logits.shape[1:] != (h, w):  # back to the frame's size: probabilities resized
            prob = _softmax(logits)
            cls = cv2.resize(_argmax0(prob), (w, h), interpolation=cv2.INTER_NEAREST)
            logits = np.log(np.stack([cv2.resize(p, (w, h)) for p in prob]) + 1e-12)
        else:
            cls = _argmax0(logits)  # the softmax keeps the order: only where needed
        masks = []
        for group, min_area in self.groups:
            mask = cls == group[0]
            for c in group[1:]:
                mask |= cls == c
            if np.count_nonzero(mask) >= min_area:
                masks.append((group, min_area, mask))
        if not masks:
            return []
        cuts = depth_cuts_within(depth, bbox_of(np.logical_or.reduce([m for *_, m in masks])))
        found: list[Instance] = []
        for group, min_area, mask in masks:
            for part in split_instances(mask, depth, cuts, min_area):
                u0, v0, u1, v1 = bbox = bbox_of(part)
                # the part's pixels in the same (row-major) order as over the whole frame
                prob = _softmax(logits[:, v0:v1, u0:u1][:, part[v0:v1, u0:u1]])
                votes = [float(prob[c].sum()) for c in group]
                c = group[int(np.argmax(votes))]
                score = float(prob[c].mean())
                if score >= self.min_score:
                    found.append(Instance(self.classes[c], score, part, bbox))
        return found

    @staticmethod
    def _check(
        rgb: NDArray[Any], depth: NDArray[Any]
    ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        rgb, depth = np.asarray(rgb), np.asarray(depth)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise SegmenterError(f"rgb must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
        if depth.shape != rgb.shape[:2]:
            raise SegmenterError(f"depth {depth.shape} does not match rgb {rgb.shape[:2]}")
        depth = depth.astype(np.float32)
        if not np.isfinite(depth).all():  # no return: 0
            depth = np.nan_to_num(depth, copy=False, nan=0.0, posinf=0.0)
        return rgb, depth


class TruthSegmenter:
    """The sim's instance labels as `Instance`s (sim truth: ablation and evaluation only)."""

    def __init__(self, classes: tuple[str, ...] = ("bottle", "can", "box", "person")) -> None:
        self.classes = classes

    def segment(self, labels: NDArray[np.integer], instances: dict[int, str]) -> list[Instance]:
        """One `Instance` (score 1) per labelled id whose class (its prefix) is known."""
        labels = np.asarray(labels)
        found: list[Instance] = []
        present = set(np.unique(labels).tolist())
        for label, truth_id in sorted(instances.items()):
            cls = truth_id.rsplit("_", 1)[0]
            if cls not in self.classes or label not in present:
                continue
            mask = labels == label
            found.append(Instance(cls, 1.0, mask, bbox_of(mask), truth_id))
        return found
