"""The robot does not see people inside itself.

The network, trained on the sim's renders, sometimes calls parts of the robot (the arm
folded in front of the head camera, a leg seen by the wrist camera) a person. No person
can stand inside the robot's own footprint, so a person detection whose robust centroid
in `base_yaw` lies within the footprint (`common.robot.FOOTPRINT_BOUNDS`, the arm
stowed) grown by `margin_m` is the robot seeing itself, and is dropped before anyone
(the map, navigation's people layer, the mission) can act on it. Artifacts are kept:
the object a grasp approaches sits in front of the base, within reach.

Nor does it see people lying on the floor. The network never saw an object lying on a
floor in training, and calls a bottle knocked down from the gripper a person (0.9, seen
from 1-1.4 m; the map then held a person at the robot's feet and the arm slowed for
them). A person detection whose top shows in the frame (its mask clear of the frame's
upper and side edges) and whose points stay below `PERSON_MIN_TOP_M` (their
`TOP_QUANTILE`) is no standing person, and is dropped too (`is_flat`). Only its top is
judged: a person cut off by the frame's edges, or seen only from the knees down under a
table, stays. On the dataset's renders of hall seeds 0-3 (both plans, 442 person
detections: 276 real, 166 false) it drops 6 false ones and no real one (with the top
edge alone judged, 10 false and 2 real: slivers of a leg at the frame's left edge).
"""

from __future__ import annotations

import numpy as np

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


#: m above the floor (world z): a person's points all below this are no standing person.
PERSON_MIN_TOP_M = 0.5
#: The share of a detection's points below its top (robust to a few stray ones).
TOP_QUANTILE = 0.95


def is_flat(found: Detected, frame_width: int) -> bool:
    """Whether `found` (in a frame `frame_width` pixels wide) is a person whose whole
    height shows and stays below `PERSON_MIN_TOP_M` (see the module docstring)."""
    det = found.detection
    u0, v0, u1, _ = det.bbox
    cut = v0 == 0 or u0 == 0 or u1 >= frame_width
    if det.class_name != "person" or cut or len(found.points_world) == 0:
        return False
    top = float(np.quantile(found.points_world[:, 2], TOP_QUANTILE))
    return top < PERSON_MIN_TOP_M


def drop_self(detected: list[Detected], frame_width: int) -> tuple[list[Detected], int]:
    """The detections (of a frame `frame_width` pixels wide) that are neither the robot
    itself nor a person lying flat (`is_flat`), and how many were."""
    kept = [d for d in detected if not is_self(d.detection) and not is_flat(d, frame_width)]
    return kept, len(detected) - len(kept)
