"""Detections for the semantic map's unit tests: a small whole mask at a world point, seen
by a camera at the world origin."""

from __future__ import annotations

import numpy as np

from common.messages import to_wire
from common.messages.perception import Detection


def detection(cls: str, x: float, y: float, z: float = 0.5) -> Detection:
    """A `cls` detection whose centroid and axis point are (x, y, z), from d_obj = |(x, y)|."""
    p = (x, y, z)
    return Detection(
        class_name=cls,
        score=0.9,
        bbox=(10, 10, 12, 12),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=p,
        centroid_in_world=p,
        axis_in_world=p,
        extent=(0.1, 0.1, 0.1),
        d_obj=float(np.hypot(x, y)),
        theta_obj=0.0,
        n_points=50,
    )
