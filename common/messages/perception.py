"""What perception publishes: instances seen by a camera, with their RGB-D geometry.

Geometry follows the paper: masked depth → points (eq. 1) → robust centroid; d_obj and
θ_obj = atan2(y, x) of the centroid in `base_yaw` (the base at its height, yaw only, z up),
so they do not move when the trunk pitches (eq. 2).
"""

from __future__ import annotations

from typing import Literal

from common.messages.arrays import Array
from common.messages.base import (
    ClassName,
    EntityId,
    Finite,
    Mat4,
    Message,
    NonNegative,
    StampNs,
    Unit,
    Vec3,
)


class Detection(Message, frozen=True):
    """One segmented instance.

    class_name: bottle, can, box, person, …; score: [0, 1].
    bbox: (u0, v0, u1, v1) pixels, inclusive-exclusive. mask: (v1-v0, u1-u0) uint8 crop, 1 inside.
    centroid_in_base_yaw, centroid_in_world: (3,) m, the visible points' robust centroid.
    axis_in_world: (3,) m, the object's vertical axis at the visible points' mid-height
        (for upright cylinders about a radius behind the visible surface; boxes: the
        footprint's centre; otherwise the centroid); extent: (3,) m, the object's size
        along the fit's x, y (at `yaw_in_world`) and z (cylinders: 2r, 2r, height).
    d_obj: m, horizontal distance of the centroid in base_yaw; theta_obj: rad, its heading.
    n_points: points behind the centroid. map_id: the semantic map's id, when associated.
    axis_in_base_yaw: (3,) m, the axis point in base_yaw at capture (what a grasp needs).
    shape: the fit behind axis and extent — `cylinder` (bottles, cans: rings about one
        vertical axis), `box` (the footprint's rectangle) or `centroid` (no shape model).
    yaw_in_world: rad, the box fit's x axis about z (0 for the others).
    radius: m, the cylinder fit's largest ring (0 for the others).
    axis_fallback: the visible arc was too short to fit a circle: the axis is one
        radius (half the visible width) behind the centroid along the line of sight.
    fit_rms_m: m, the points' rms distance to the fitted surface (0 when not fitted).
    network_class: the segmenter's class when perception's shape check changed it (a
        can or a box near the camera is told by whether its depth fits a cylinder);
        None when `class_name` is the segmenter's.
    """

    class_name: ClassName
    score: Unit
    bbox: tuple[int, int, int, int]
    mask: Array
    centroid_in_base_yaw: Vec3
    centroid_in_world: Vec3
    axis_in_world: Vec3
    extent: Vec3
    d_obj: Finite
    theta_obj: Finite
    n_points: int
    map_id: EntityId | None = None
    axis_in_base_yaw: Vec3 = (0.0, 0.0, 0.0)
    shape: Literal["cylinder", "box", "centroid"] = "centroid"
    yaw_in_world: Finite = 0.0
    radius: NonNegative = 0.0
    axis_fallback: bool = False
    fit_rms_m: NonNegative = 0.0
    network_class: ClassName | None = None


class Detections(Message, frozen=True):
    """`dume/<r>/perception/detections`: everything one camera frame showed.

    stamp_ns: the frame's capture stamp (= perception's tick: published every tick for
        every camera, empty lists too). T_world_base: the base at capture.
    segmenter: `network` or `truth` (the ablation that reads the renderer's ids).
    reason: why no frame was processed (no frame at this tick, the segmenter is
        unavailable, a bad frame); empty when it was.
    process_ms, segment_ms: wall time this frame took in perception (decode, segment,
        geometry) and in the segmenter alone, ms — for monitoring, never for control.
    """

    stamp_ns: StampNs
    camera: str
    T_world_base: Mat4
    segmenter: Literal["network", "truth"]
    detections: list[Detection]
    reason: str = ""
    process_ms: NonNegative = 0.0
    segment_ms: NonNegative = 0.0

    WALL_CLOCK = ("process_ms", "segment_ms")


class LocateRequest(Message, frozen=True):
    """`dume/<r>/perception/locate`: the best current instance of a class or map id.

    Exactly one of class_name and map_id. camera: only this camera's detections (None:
    any). max_age_s: ignore detections older than this (sim time) behind perception's
    newest tick. Best: the highest score, then the most points. A map id is looked up
    in the semantic map and matched to the nearest detection of its class within
    `perception.locate_gate_m` of its mapped position.
    """

    class_name: ClassName | None = None
    map_id: EntityId | None = None
    camera: str | None = None
    max_age_s: Finite = 1.0


class LocateReply(Message, frozen=True):
    """The instance found, with the frame's stamp, or none (stamp_ns: perception's newest
    tick). A detection found by map id carries that `map_id`."""

    stamp_ns: StampNs
    found: bool
    camera: str = ""
    detection: Detection | None = None
