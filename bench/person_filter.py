"""`dume bench person-filter`: what perception's person filters drop, real and false.

The network's person detections on the dataset's renders (`services.sim.dataset.render_seed`:
the small world's seeds 0-2 and the hall's 0-3 from the `train` plan, the hall's 0-3 from
the `heldout` plan), measured as the robot measures them (`pipeline.detect`, the network
as perception runs it, no depth noise). A detection is real when most of its mask's
pixels are a person's in the sim's labels (truth), else false, named by what it lies on
(`table`, `bench`, `robot`, ...). Each is judged by `self_filter`'s rules in their order
(`is_self`, `is_flat`, `is_slab`): the figures are how many real and false ones each rule
drops and how many pass, by what the false ones are. Deterministic for the model.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from collections import Counter
from typing import Any

import numpy as np

from common.config import load_config, resolve
from common.messages.arrays import to_wire
from common.messages.sim import CameraFrame
from services.perception.pipeline import Detected, detect, mask_of
from services.perception.segmenter import Segmenter
from services.perception.self_filter import is_flat, is_self, is_slab
from services.sim.dataset import Frame, render_seed

#: (world, seed, plan) of the renders judged.
RENDERS = (
    *(("small", s, "train") for s in range(3)),
    *(("hall", s, "train") for s in range(4)),
    *(("hall", s, "heldout") for s in range(4)),
)


def _frame(f: Frame) -> CameraFrame:
    depth = f.depth_mm.astype(np.float32) * np.float32(1e-3)
    fx, fy, cx, cy = f.intrinsics
    return CameraFrame(
        stamp_ns=0, camera=f.camera, width=depth.shape[1], height=depth.shape[0],
        fx=fx, fy=fy, cx=cx, cy=cy, rgb=to_wire(f.rgb), depth=to_wire(depth),
        T_base_camera=tuple(f.T_base_camera.ravel().tolist()),
    )  # fmt: skip


def rule_of(found: Detected, width: int) -> str:
    """The first of `self_filter`'s rules that drops `found`, or `kept`."""
    if is_self(found.detection):
        return "self"
    if is_flat(found, width):
        return "flat"
    return "slab" if is_slab(found) else "kept"


def bench_person_filter() -> dict[str, Any]:
    """The figures of the module docstring."""
    perception = load_config().perception
    net = Segmenter(resolve(perception.model), threads=perception.dnn_threads or None)
    counts: Counter[tuple[str, bool]] = Counter()
    false_by: Counter[tuple[str, str]] = Counter()
    frames = 0
    for world, seed, plan in RENDERS:
        names, shots = render_seed(seed, world, plan)
        for f in shots:
            frames += 1
            frame = _frame(f)
            depth = f.depth_mm.astype(np.float32) * np.float32(1e-3)
            found = net.segment(f.rgb, depth)
            for d in detect(frame, f.T_world_base, found, perception.min_score):
                if d.detection.class_name != "person":
                    continue
                mask = mask_of(d.detection, depth.shape)
                labels, n = np.unique(f.labels[mask], return_counts=True)
                under = names.get(int(labels[np.argmax(n)]), "background")
                real = under.startswith("person")
                rule = rule_of(d, frame.width)
                counts[(rule, real)] += 1
                if not real:
                    false_by[(rule, under.rsplit("_", 1)[0])] += 1
    rules = ("self", "flat", "slab", "kept")
    out: dict[str, Any] = {
        "renders": [f"{w} {s} {p}" for w, s, p in RENDERS],
        "frames": frames,
        "people": {"real": sum(v for (_, r), v in counts.items() if r),
                   "false": sum(v for (_, r), v in counts.items() if not r)},
        "by_rule": {k: {"real": counts[(k, True)], "false": counts[(k, False)]} for k in rules},
        "false_by_what": {k: dict(sorted((w, v) for (r, w), v in false_by.items() if r == k))
                          for k in rules},
    }  # fmt: skip
    for k in rules:
        print(f"{k:>5}: {counts[(k, True)]:4d} real, {counts[(k, False)]:4d} false")
    return out
