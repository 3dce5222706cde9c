"""People seen inside the robot's own footprint are the robot itself and are dropped."""

from __future__ import annotations

import numpy as np

from common.messages.arrays import to_wire
from common.messages.perception import Detection
from common.robot import FOOTPRINT_BOUNDS
from services.perception.pipeline import Detected
from services.perception.self_filter import SELF_MARGIN_M, drop_self, is_self


def _det(cls: str, x: float, y: float) -> Detection:
    return Detection(
        class_name=cls,
        score=0.8,
        bbox=(0, 0, 2, 2),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=(x, y, 0.6),
        centroid_in_world=(x, y, 0.6),
        axis_in_world=(x, y, 0.6),
        extent=(0.3, 0.3, 0.6),
        d_obj=float(np.hypot(x, y)),
        theta_obj=float(np.arctan2(y, x)),
        n_points=200,
    )


def test_a_person_inside_the_footprint_or_just_beyond_is_the_robot() -> None:
    _, x1, y0, _ = FOOTPRINT_BOUNDS
    assert is_self(_det("person", 0.0, 0.0))
    assert is_self(_det("person", x1 + SELF_MARGIN_M - 0.01, 0.0))
    assert is_self(_det("person", 0.0, y0 - SELF_MARGIN_M + 0.01))


def test_people_outside_and_artifacts_anywhere_are_kept() -> None:
    x0, x1, _, y1 = FOOTPRINT_BOUNDS
    assert not is_self(_det("person", x1 + SELF_MARGIN_M + 0.05, 0.0))
    assert not is_self(_det("person", 0.0, y1 + 0.6))
    assert not is_self(_det("person", x0 - 0.8, 0.0))
    assert not is_self(_det("bottle", 0.3, 0.0)), "the object in front of the base is kept"
    detected = [
        Detected(_det("person", 0.1, 0.0), np.zeros((0, 3))),
        Detected(_det("person", 3.0, 1.0), np.zeros((0, 3))),
        Detected(_det("bottle", 0.5, 0.0), np.zeros((0, 3))),
    ]
    kept, dropped = drop_self(detected)
    assert dropped == 1
    assert [d.detection.class_name for d in kept] == ["person", "bottle"]
