"""A YOLOv8-seg decoder: drop in an ultralytics-exported ONNX model for a real camera.

Such a model (`yolo export format=onnx` of a `-seg` model) takes a letterboxed (1, 3, S, S)
RGB image in [0, 1] and returns
- `output0` (1, 4 + nc + 32, N): per candidate the box centre, width and height in input
  pixels, nc class scores (already sigmoid) and 32 mask coefficients;
- `output1` (1, 32, S/4, S/4): the prototype masks.
`decode` keeps candidates whose best class score passes `conf_threshold`, runs per-class
NMS (`cv2.dnn.NMSBoxesBatched`), forms each mask as sigmoid(coefficients · prototypes),
crops it to its box, scales it back through the letterbox to the original image and
thresholds it: the same `Instance`s as the sim-trained segmenter. `YoloSegmenter` wraps
the network, the letterbox and `decode`; class names come from the caller or from the
model's `names` metadata.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from services.perception.onnx_net import OnnxError, OnnxNet
from services.perception.segmenter import Instance, SegmenterError

N_MASK_COEFFS = 32


class Letterbox(NamedTuple):
    """How an (h, w) image sits in the square network input: input = image × scale + pad."""

    scale: float
    pad_x: int
    pad_y: int
    image_hw: tuple[int, int]
    input_hw: tuple[int, int]


def letterbox(rgb: NDArray[np.uint8], size: int) -> tuple[NDArray[np.float32], Letterbox]:
    """(1, 3, size, size) float input in [0, 1], grey-padded, and its `Letterbox`."""
    h, w = rgb.shape[:2]
    scale = min(size / h, size / w)
    nh, nw = round(h * scale), round(w * scale)
    pad_y, pad_x = (size - nh) // 2, (size - nw) // 2
    canvas = np.full((size, size, 3), 114, dtype=np.uint8)
    canvas[pad_y : pad_y + nh, pad_x : pad_x + nw] = cv2.resize(
        rgb, (nw, nh), interpolation=cv2.INTER_LINEAR
    )
    blob = canvas.astype(np.float32).transpose(2, 0, 1)[None] / np.float32(255.0)
    return blob, Letterbox(scale, pad_x, pad_y, (h, w), (size, size))


def _sigmoid(x: NDArray[np.float32]) -> NDArray[np.float32]:
    return np.asarray(1.0 / (1.0 + np.exp(-np.clip(x, -50.0, 50.0))), dtype=np.float32)


def decode(
    output0: NDArray[np.floating],
    protos: NDArray[np.floating],
    names: Sequence[str],
    box: Letterbox,
    conf_threshold: float = 0.25,
    iou_threshold: float = 0.45,
    mask_threshold: float = 0.5,
    max_instances: int = 100,
) -> list[Instance]:
    """`Instance`s in the original image from a YOLOv8-seg model's two outputs."""
    pred = np.asarray(output0, dtype=np.float32)
    proto = np.asarray(protos, dtype=np.float32)
    nc = len(names)
    if pred.ndim != 3 or pred.shape[0] != 1 or pred.shape[1] != 4 + nc + N_MASK_COEFFS:
        raise SegmenterError(f"output0 {pred.shape} is not (1, 4 + {nc} + 32, N)")
    if proto.ndim != 4 or proto.shape[:2] != (1, N_MASK_COEFFS):
        raise SegmenterError(f"prototypes {proto.shape} are not (1, 32, h, w)")
    rows = pred[0].T  # (N, 4 + nc + 32)
    scores = rows[:, 4 : 4 + nc]
    cls = scores.argmax(axis=1)
    conf = scores[np.arange(rows.shape[0]), cls]
    keep = conf >= conf_threshold
    rows, cls, conf = rows[keep], cls[keep], conf[keep]
    if rows.shape[0] == 0:
        return []
    cx, cy, bw, bh = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    xywh = np.stack([cx - bw / 2, cy - bh / 2, bw, bh], axis=1)
    picked = cv2.dnn.NMSBoxesBatched(
        xywh.tolist(), conf.tolist(), cls.tolist(), conf_threshold, iou_threshold
    )
    order = np.asarray(picked, dtype=int).reshape(-1)[:max_instances]
    _, _, mh, mw = proto.shape
    in_h, in_w = box.input_hw
    h, w = box.image_hw
    found: list[Instance] = []
    for i in order.tolist():
        coeffs = rows[i, 4 + nc :]
        small = _sigmoid(np.tensordot(coeffs, proto[0], axes=1))  # (mh, mw)
        # The box in prototype pixels: ultralytics crops there, before upsampling.
        x0, y0 = xywh[i, 0] * mw / in_w, xywh[i, 1] * mh / in_h
        x1, y1 = x0 + xywh[i, 2] * mw / in_w, y0 + xywh[i, 3] * mh / in_h
        us, vs = np.arange(mw) + 0.5, np.arange(mh) + 0.5
        inside = ((vs >= y0) & (vs < y1))[:, None] & ((us >= x0) & (us < x1))[None, :]
        small = np.where(inside, small, 0.0).astype(np.float32)
        full = cv2.resize(small, (in_w, in_h), interpolation=cv2.INTER_LINEAR)
        nh, nw = round(h * box.scale), round(w * box.scale)
        full = full[box.pad_y : box.pad_y + nh, box.pad_x : box.pad_x + nw]
        mask = cv2.resize(full, (w, h), interpolation=cv2.INTER_LINEAR) > mask_threshold
        # The box in image pixels, clipped: the mask never leaves it.
        u0 = int(np.clip(np.floor((xywh[i, 0] - box.pad_x) / box.scale), 0, w))
        v0 = int(np.clip(np.floor((xywh[i, 1] - box.pad_y) / box.scale), 0, h))
        u1 = int(np.clip(np.ceil((xywh[i, 0] + xywh[i, 2] - box.pad_x) / box.scale), 0, w))
        v1 = int(np.clip(np.ceil((xywh[i, 1] + xywh[i, 3] - box.pad_y) / box.scale), 0, h))
        clipped = np.zeros_like(mask)
        clipped[v0:v1, u0:u1] = mask[v0:v1, u0:u1]
        if not clipped.any():
            continue
        found.append(Instance(str(names[int(cls[i])]), float(conf[i]), clipped, (u0, v0, u1, v1)))
    return found


def names_from_metadata(net: OnnxNet, model: Path) -> list[str]:
    """Class names from an ultralytics export's `names` metadata."""
    if "names" not in net.metadata:
        raise SegmenterError(f"{model} has no `names` metadata; pass names")
    table: Any = ast.literal_eval(net.metadata["names"])
    return [str(table[k]) for k in sorted(table)]


class YoloSegmenter:
    """An ultralytics YOLOv8-seg ONNX model (`OnnxNet`): `segment(rgb, depth)`."""

    def __init__(
        self,
        model: Path | str,
        names: Sequence[str] | None = None,
        input_size: int = 640,
        conf_threshold: float = 0.25,
        iou_threshold: float = 0.45,
    ) -> None:
        model = Path(model)
        try:
            self.net = OnnxNet(model)
        except OnnxError as exc:
            raise SegmenterError(str(exc)) from exc
        self.names = list(names) if names is not None else names_from_metadata(self.net, model)
        self.input_size = input_size
        self.conf_threshold, self.iou_threshold = conf_threshold, iou_threshold

    def segment(
        self, rgb: NDArray[np.uint8], depth: NDArray[np.floating] | None = None
    ) -> list[Instance]:
        """Instances in an (H, W, 3) uint8 RGB image (depth is not used)."""
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise SegmenterError(f"rgb must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
        blob, box = letterbox(rgb, self.input_size)
        try:
            outs = self.net.run(blob)
        except OnnxError as exc:
            raise SegmenterError(str(exc)) from exc
        # (1, C, N) before (1, 32, h, w), whatever order the model lists them in
        output0, protos = sorted(outs, key=np.ndim)
        return decode(output0, protos, self.names, box, self.conf_threshold, self.iou_threshold)
