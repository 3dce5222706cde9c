"""The robot does not see people inside itself.

The network, trained on the sim's renders, sometimes calls parts of the robot (the arm
folded in front of the head camera, a leg seen by the wrist camera) a person. No person
can stand inside the robot's own footprint, so a person detection whose robust centroid
in `base_yaw` lies within the footprint (`common.robot.FOOTPRINT_BOUNDS`, the arm
stowed) grown by `margin_m` is the robot seeing itself, and is dropped before anyone
(the map, navigation's people layer, the mission) can act on it. Artifacts are kept:
the object a grasp approaches sits in front of the base, within reach.
"""

from __future__ import annotations

from common.messages.perception import Detection
from common.robot import FOOTPRINT_BOUNDS
from services.perception.pipeline import Detected

#: How far beyond the stowed footprint the robot's own parts reach (the arm in `look`,
#: the legs mid-swing), m.
SELF_MARGIN_M = 0.15


def is_self(det: Detection, margin_m: float = SELF_MARGIN_M) -> bool:
    """Whether `det` is a person seen inside the robot's own footprint."""
    if det.class_name != "person":
        return False
    x, y, _ = det.centroid_in_base_yaw
    x0, x1, y0, y1 = FOOTPRINT_BOUNDS
    return x0 - margin_m <= x <= x1 + margin_m and y0 - margin_m <= y <= y1 + margin_m


def drop_self(detected: list[Detected]) -> tuple[list[Detected], int]:
    """The detections that are not the robot itself, and how many were."""
    kept = [d for d in detected if not is_self(d.detection)]
    return kept, len(detected) - len(kept)
