"""Training data from the sim's `.npz` shards: class maps, network inputs, augmented crops.

A shard (written by the simulator's dataset tool) holds RGB, depth in mm, instance labels
and each label's truth id (`bottle_1`, `person_2`, `table_1`, `robot`); the class of an id is
its prefix, and ids whose prefix is not in `CLASSES` are background. Everything is kept in
memory as uint8/uint16 (a few hundred MB for a few thousand frames at 320 × 240). No torch
here: the batches are numpy.

Augmentation, drawn from one `numpy.random.Generator` (so the data order and the crops
follow the training seed): crops biased towards object pixels (small artifacts would
otherwise be rare), horizontal flips, per-channel gain and offset, random channel order
(colour must not decide the class), Gaussian pixel noise, and on most crops the robot's
stereo depth errors (`common.camera.stereo_depth`: noise growing with z², no return
beside near edges, dropouts), on the others depth noise proportional to depth with a
few dropped pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from common.camera import stereo_depth
from common.config import DepthNoiseSettings

CLASSES: tuple[str, ...] = ("background", "bottle", "can", "box", "person")
#: The network's input format (recorded in the model's sidecar for the runtime).
MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)
#: Inverse depth saturates here (1/m): nearer than 0.2 m is all the same.
INV_DEPTH_MAX = 5.0
#: The sim's stereo depth model (its default settings), and the share of training crops
#: that get it: a network trained on clean renders alone lost a fifth of its bottle IoU
#: and put boxes half a metre off on the robot's noisy depth.
STEREO = DepthNoiseSettings()
STEREO_SHARE = 0.8


def class_of(truth_id: str) -> str:
    """`bottle_2` → `bottle`; ids of other things map to `background`."""
    prefix = truth_id.rsplit("_", 1)[0]
    return prefix if prefix in CLASSES else "background"


@dataclass
class Frames:
    """Frames from shards: images, depth (mm), class maps and instance labels with their ids."""

    rgb: NDArray[np.uint8]  # (N, H, W, 3)
    depth_mm: NDArray[np.uint16]  # (N, H, W)
    classes: NDArray[np.uint8]  # (N, H, W) index into CLASSES
    labels: NDArray[np.uint16]  # (N, H, W) instance labels
    names: list[dict[int, str]]  # per frame: label → truth id
    camera: list[str]
    seeds: list[int]

    def __len__(self) -> int:
        return int(self.rgb.shape[0])


def load_frames(paths: Sequence[Path]) -> Frames:
    """Read shards into one `Frames` (in the order given)."""
    rgb, depth, classes, labels, names, camera, seeds = [], [], [], [], [], [], []
    for path in paths:
        with np.load(path) as shard:
            ids = shard["label_ids"].tolist()
            id_names = [str(n) for n in shard["label_names"]]
            lut = np.zeros(int(shard["labels"].max(initial=0)) + 1, dtype=np.uint8)
            for label, name in zip(ids, id_names, strict=True):
                if label < lut.size:
                    lut[label] = CLASSES.index(class_of(name))
            n = int(shard["rgb"].shape[0])
            rgb.append(shard["rgb"])
            depth.append(shard["depth_mm"])
            labels.append(shard["labels"])
            classes.append(lut[shard["labels"]])
            names += [dict(zip(ids, id_names, strict=True))] * n
            camera += [str(c) for c in shard["camera"]]
            seeds += [int(shard["seed"])] * n
    if not rgb:
        raise ValueError("no shards to load")
    return Frames(
        rgb=np.concatenate(rgb),
        depth_mm=np.concatenate(depth),
        classes=np.concatenate(classes),
        labels=np.concatenate(labels),
        names=names,
        camera=camera,
        seeds=seeds,
    )


def network_input(rgb: NDArray[np.floating], depth_m: NDArray[np.floating]) -> NDArray[np.float32]:
    """(N, H, W, 3) RGB in [0, 255] and (N, H, W) depth (m, 0 = none) → (N, 4, H, W)."""
    mean, std = np.asarray(MEAN, np.float32), np.asarray(STD, np.float32)
    x = (np.asarray(rgb, dtype=np.float32) / np.float32(255.0) - mean) / std
    d = np.asarray(depth_m, dtype=np.float32)
    inv = np.where(d > 0, 1.0 / np.maximum(d, 1e-3), 0.0)
    inv = np.minimum(inv, INV_DEPTH_MAX) / INV_DEPTH_MAX
    return np.concatenate([x.transpose(0, 3, 1, 2), inv[:, None].astype(np.float32)], axis=1)


class Sampler:
    """Augmented training batches of crops (see the module docstring)."""

    def __init__(
        self,
        frames: Frames,
        rng: np.random.Generator,
        crop_hw: tuple[int, int] = (160, 224),
        object_bias: float = 0.7,
    ) -> None:
        self.frames, self.rng = frames, rng
        self.crop_hw, self.object_bias = crop_hw, object_bias
        # Object pixels per frame, subsampled: where biased crops centre.
        self._objects = [np.flatnonzero(c.ravel()[::7]) * 7 for c in frames.classes]

    def _corner(self, k: int) -> tuple[int, int]:
        h, w = self.frames.classes.shape[1:]
        ch, cw = self.crop_hw
        objects = self._objects[k]
        if objects.size and self.rng.random() < self.object_bias:
            v, u = divmod(int(objects[self.rng.integers(objects.size)]), w)
            v0 = v - int(self.rng.integers(ch // 4, 3 * ch // 4))
            u0 = u - int(self.rng.integers(cw // 4, 3 * cw // 4))
        else:
            v0, u0 = int(self.rng.integers(h - ch + 1)), int(self.rng.integers(w - cw + 1))
        return int(np.clip(v0, 0, h - ch)), int(np.clip(u0, 0, w - cw))

    def _depth_noise(self, d: NDArray[np.float32]) -> NDArray[np.float32]:
        """The robot's depth camera's errors (`common.camera.stereo_depth`, the sim's model
        with its settings scaled ×0.5–2) on `STEREO_SHARE` of the crops; the others get
        the range-proportional noise and the dropouts alone."""
        rng = self.rng
        if rng.random() < STEREO_SHARE:
            s = STEREO
            k = rng.uniform(0.5, 2.0, 3)
            return stereo_depth(
                d, s.sigma_per_m2 * k[0], s.edge_jump_m * k[1], s.dropout * k[2], rng
            )
        out = (d * (1.0 + rng.normal(0.0, 0.004, d.shape))).astype(np.float32)
        out[rng.random(d.shape) < rng.uniform(0.0, 0.02)] = 0.0
        return out

    def batch(self, size: int) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
        """(size, 4, ch, cw) inputs and (size, ch, cw) class targets."""
        rng, ch, cw = self.rng, *self.crop_hw
        idx = rng.integers(len(self.frames), size=size)
        rgb = np.empty((size, ch, cw, 3), np.float32)
        depth = np.empty((size, ch, cw), np.float32)
        target = np.empty((size, ch, cw), np.int64)
        for i, k in enumerate(idx.tolist()):
            v0, u0 = self._corner(k)
            win = (slice(v0, v0 + ch), slice(u0, u0 + cw))
            r = self.frames.rgb[k][win].astype(np.float32)
            d = self.frames.depth_mm[k][win].astype(np.float32) * 1e-3
            t = self.frames.classes[k][win]
            if rng.random() < 0.5:
                r, d, t = r[:, ::-1], d[:, ::-1], t[:, ::-1]
            r = r[..., rng.permutation(3)] if rng.random() < 0.3 else r
            r = r * rng.uniform(0.6, 1.4, 3) + rng.uniform(-25, 25, 3)
            r = r + rng.normal(0.0, rng.uniform(0.0, 6.0), r.shape)
            d = self._depth_noise(d)
            rgb[i], depth[i], target[i] = np.clip(r, 0, 255), d, t
        return network_input(rgb, depth), target


def class_weights(frames: Frames, power: float = 0.5, max_weight: float = 10.0) -> NDArray:
    """Per-class loss weights ∝ frequency^-power, background 1, capped at `max_weight`."""
    counts = np.bincount(frames.classes[:, ::4, ::4].ravel(), minlength=len(CLASSES))
    freq = counts / max(1, counts.sum())
    w = (freq[0] / np.maximum(freq, 1e-9)) ** power
    return np.minimum(w, max_weight).astype(np.float32)
