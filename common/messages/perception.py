"""What perception publishes: instances seen by a camera, with their RGB-D geometry.

Geometry follows the paper: masked depth → points (eq. 1) → robust centroid; d_obj and
θ_obj = atan2(y, x) of the centroid in `base_yaw` (the base at its height, yaw only, z up),
so they do not move when the trunk pitches (eq. 2).
"""

from __future__ import annotations

from typing import Literal

from common.messages.arrays import Array
from common.messages.base import ClassName, EntityId, Finite, Mat4, Message, StampNs, Unit, Vec3


class Detection(Message, frozen=True):
    """One segmented instance.

    class_name: bottle, can, box, person, …; score: [0, 1].
    bbox: (u0, v0, u1, v1) pixels, inclusive-exclusive. mask: (v1-v0, u1-u0) uint8 crop, 1 inside.
    centroid_in_base_yaw, centroid_in_world: (3,) m, the visible points' robust centroid.
    axis_in_world: (3,) m, estimated object axis point (for upright cylinders about a radius
        behind the visible surface); extent: (3,) m, the object's size estimate.
    d_obj: m, horizontal distance of the centroid in base_yaw; theta_obj: rad, its heading.
    n_points: points behind the centroid. map_id: the semantic map's id, when associated.
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


class Detections(Message, frozen=True):
    """`dume/<r>/perception/detections`: everything one camera frame showed.

    stamp_ns: the frame's capture stamp. T_world_base: the base at capture.
    segmenter: `network` or `truth` (the ablation that reads the renderer's ids).
    """

    stamp_ns: StampNs
    camera: str
    T_world_base: Mat4
    segmenter: Literal["network", "truth"]
    detections: list[Detection]


class LocateRequest(Message, frozen=True):
    """`dume/<r>/perception/locate`: the best current instance of a class or map id.

    Exactly one of class_name and map_id. max_age_s: ignore older detections.
    """

    class_name: ClassName | None = None
    map_id: EntityId | None = None
    camera: str | None = None
    max_age_s: Finite = 1.0


class LocateReply(Message, frozen=True):
    """The instance found, with the frame's stamp, or none."""

    stamp_ns: StampNs
    found: bool
    camera: str = ""
    detection: Detection | None = None
