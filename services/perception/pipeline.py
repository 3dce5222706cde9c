"""A camera frame and its segmented instances → `Detection`s.

`detect(frame, T_world_base, instances, min_score, shape_check)` measures every instance
scored at least `min_score` (`measure.measure` on its mask's bounding box; a can's or a
box's class checked by its shape near the camera) and packs the message;
instances with too few depth points are left out. The instances come from the
segmenter (`segmenter.Segmenter`, or `TruthSegmenter` for the truth ablation). No
transport here: `node.py` feeds it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from common.camera import PinholeCamera
from common.geometry import BoolArray
from common.messages import as_numpy, to_wire
from common.messages.perception import Detection
from common.messages.sim import CameraFrame
from services.perception.measure import FrameGeometry, Measurement, ShapeCheck, measure

#: The classes perception reports (the network's, and what truth labels are mapped to).
CLASSES = ("bottle", "can", "box", "person")


class Segmented(Protocol):
    """What `detect` needs of an instance (a segmenter's `Instance`)."""

    @property
    def class_name(self) -> str: ...
    @property
    def score(self) -> float: ...
    @property
    def mask(self) -> BoolArray: ...


def frame_geometry(frame: CameraFrame, T_world_base: npt.ArrayLike) -> FrameGeometry:
    """The frame's intrinsics and transforms as numpy; the base at capture (4×4) is the
    robot's estimate (`odom` at the frame's stamp)."""
    return FrameGeometry(
        camera=PinholeCamera(frame.fx, frame.fy, frame.cx, frame.cy),
        T_base_camera=np.asarray(frame.T_base_camera, dtype=float).reshape(4, 4),
        T_world_base=np.asarray(T_world_base, dtype=float).reshape(4, 4),
    )


def bbox_of(mask: BoolArray) -> tuple[int, int, int, int] | None:
    """(u0, v0, u1, v1), inclusive-exclusive, of a mask's pixels; None when empty."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return None
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def _vec(x: npt.ArrayLike) -> tuple[float, float, float]:
    a = np.asarray(x, dtype=float)
    return float(a[0]), float(a[1]), float(a[2])


def to_detection(
    inst: Segmented, bbox: tuple[int, int, int, int], crop: BoolArray, m: Measurement
) -> Detection:
    fit = m.fit_base_yaw
    return Detection(
        class_name=m.class_name or inst.class_name,
        score=float(min(max(inst.score, 0.0), 1.0)),
        bbox=bbox,
        mask=to_wire(crop.astype(np.uint8)),
        centroid_in_base_yaw=_vec(m.centroid_base_yaw),
        centroid_in_world=_vec(m.centroid_world),
        axis_in_world=_vec(m.axis_world),
        extent=_vec(fit.extent),
        d_obj=m.d_obj,
        theta_obj=m.theta_obj,
        n_points=m.n_points,
        axis_in_base_yaw=_vec(m.axis_base_yaw),
        shape=fit.shape,
        yaw_in_world=m.yaw_world if fit.shape == "box" else 0.0,
        radius=fit.radius,
        axis_fallback=fit.fallback,
        fit_rms_m=fit.rms_m if math.isfinite(fit.rms_m) else 0.0,
        network_class=m.network_class or None,
    )


@dataclass(frozen=True)
class Detected:
    """A detection with what the logs want beside it: the inlier points in the world."""

    detection: Detection
    points_world: npt.NDArray[np.float64]


def detect(
    frame: CameraFrame,
    T_world_base: npt.ArrayLike,
    instances: Iterable[Segmented],
    min_score: float,
    shape_check: ShapeCheck | None = None,
) -> list[Detected]:
    """Measure each instance scored ≥ `min_score` (the base at `T_world_base`, 4×4, at
    capture), a can's or box's class checked by its shape with `shape_check`
    (`measure.ShapeCheck`); those without depth are left out."""
    depth = np.asarray(as_numpy(frame.depth))
    geo = frame_geometry(frame, T_world_base)
    out = []
    for inst in instances:
        if inst.score < min_score:
            continue
        if inst.mask.shape != depth.shape:
            raise ValueError(
                f"{inst.class_name} mask {inst.mask.shape} does not match depth {depth.shape}"
            )
        bbox = bbox_of(inst.mask)
        if bbox is None:
            continue
        u0, v0, u1, v1 = bbox
        crop = inst.mask[v0:v1, u0:u1]
        m = measure(geo, depth[v0:v1, u0:u1], crop, (u0, v0), inst.class_name, shape_check)
        if m is None:
            continue
        out.append(Detected(to_detection(inst, bbox, crop, m), m.points_world))
    return out


def class_text(d: Detection) -> str:
    """A detection's class for a person: `box (network: can)` when the shape check
    changed the network's."""
    return f"{d.class_name} (network: {d.network_class})" if d.network_class else d.class_name


def mask_of(detection: Detection, shape: Sequence[int]) -> BoolArray:
    """A detection's full-frame (H, W) mask from its crop and bounding box."""
    full = np.zeros(tuple(shape[:2]), dtype=bool)
    u0, v0, u1, v1 = detection.bbox
    full[v0:v1, u0:u1] = np.asarray(as_numpy(detection.mask)).astype(bool)
    return full
