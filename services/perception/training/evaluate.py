"""Validation figures of an exported model, run exactly as the robot runs it.

Every held-out frame goes through the runtime `Segmenter` (OpenCV DNN, instance
separation included) and is matched against `TruthSegmenter` instances of its labels:
- bottle mask IoU: mean over bottles in wrist-camera frames with ≥ `CLOSE_UP_PIXELS` truth
  pixels (the close-up views the grasp relies on), and over every bottle with ≥ 50 pixels;
- person recall over people with ≥ 500 truth pixels within 8 m (`metrics.person_recall`);
- mean IoU per class; predicted instances matching no truth, per frame;
- the network's forward pass (onnxruntime) and the whole `segment` call, ms p50/p95.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from services.perception import metrics
from services.perception.segmenter import Segmenter, TruthSegmenter
from services.perception.training.data import CLASSES, Frames

CLOSE_UP_PIXELS = 150


def _percentiles(ms: list[float]) -> dict[str, float]:
    return {
        "p50": round(float(np.percentile(ms, 50)), 2),
        "p95": round(float(np.percentile(ms, 95)), 2),
    }


def evaluate(model: Path, frames: Frames) -> dict[str, Any]:
    """Validation figures of `model` on `frames` (see the module docstring)."""
    net = Segmenter(model)
    truth_seg = TruthSegmenter(tuple(c for c in CLASSES if c != "background"))
    matches: list[metrics.Match] = []
    close_bottles: list[float] = []
    forward_ms: list[float] = []
    segment_ms: list[float] = []
    unmatched = 0
    for k in range(len(frames)):
        rgb = frames.rgb[k]
        depth = frames.depth_mm[k].astype(np.float32) * 1e-3
        blob = net.blob(rgb, depth)
        t0 = time.perf_counter()
        net.forward(blob)
        forward_ms.append((time.perf_counter() - t0) * 1e3)
        t0 = time.perf_counter()
        predicted = net.segment(rgb, depth)
        segment_ms.append((time.perf_counter() - t0) * 1e3)
        truth = truth_seg.segment(frames.labels[k], frames.names[k])
        found = metrics.match_instances(predicted, truth, [t.truth_id or "" for t in truth], depth)
        matches += found
        unmatched += len(predicted) - sum(m.matched is not None for m in found)
        if frames.camera[k] == "camera_wrist":
            close_bottles += [
                m.iou for m in found if m.class_name == "bottle" and m.pixels >= CLOSE_UP_PIXELS
            ]
    found_people, counted_people = metrics.person_recall(matches)
    per_class = {c: metrics.mean_iou(matches, c, min_pixels=50) for c in CLASSES[1:]}
    return {
        "frames": len(frames),
        "bottle_iou_close_up": round(float(np.mean(close_bottles)), 4) if close_bottles else None,
        "bottles_close_up": len(close_bottles),
        "bottle_iou_all": per_class["bottle"] and round(per_class["bottle"], 4),
        "person_recall": round(float(found_people / counted_people), 4) if counted_people else None,
        "people_counted": counted_people,
        "false_instances_per_frame": round(unmatched / max(1, len(frames)), 3),
        "mean_iou": {c: (None if v is None else round(v, 4)) for c, v in per_class.items()},
        "forward_ms": _percentiles(forward_ms),
        "segment_ms": _percentiles(segment_ms),
    }
