"""From a `CameraFrame` and masks to `Detection` messages, and the locate rules.

The frame is ray-cast (`perception_raycast`): a bottle on a table seen from a camera on
a pitched trunk, so the message's numbers can be checked against the scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from common.bus import RequestError
from common.geometry import make_T, rot_y, rot_z
from common.messages import decode, encode, to_wire
from common.messages.perception import Detection, Detections, LocateRequest
from common.messages.sim import CameraFrame
from common.robot_description import R_FORWARD_OPTICAL
from services.perception.locate import (
    RecentDetections,
    best_of_class,
    check_request,
    nearest_to,
)
from services.perception.measure import ShapeCheck
from services.perception.pipeline import CLASSES, class_text, detect, mask_of
from tests.unit.perception_raycast import Plane, Shape, UprightCylinder, render

W, H = 320, 240
K = (216.5, 216.5, (W - 1) / 2, (H - 1) / 2)
T_WORLD_BASE = make_T(rot_z(0.4) @ rot_y(0.05), (0.5, -0.2, 0.55))
T_BASE_CAMERA = make_T(rot_y(math.radians(20)) @ R_FORWARD_OPTICAL, (0.3, 0.0, 0.5))
BOTTLE_XY = (
    0.5 + 1.0 * math.cos(0.4) - 0.1 * math.sin(0.4),
    -0.2 + 1.0 * math.sin(0.4) + 0.1 * math.cos(0.4),
)


@dataclass(frozen=True)
class Inst:
    class_name: str
    score: float
    mask: np.ndarray


def _frame() -> tuple[CameraFrame, np.ndarray]:
    shapes: list[Shape] = [
        Plane((0, 0, 0.8), (0, 0, 1)),
        UprightCylinder(BOTTLE_XY, 0.03, 0.8, 0.95),
    ]
    depth, labels, _ = render(shapes, T_WORLD_BASE @ T_BASE_CAMERA, K, W, H)
    frame = CameraFrame(
        stamp_ns=300_000_000,
        camera="camera_wrist",
        width=W,
        height=H,
        fx=K[0],
        fy=K[1],
        cx=K[2],
        cy=K[3],
        rgb=to_wire(np.zeros((H, W, 3), dtype=np.uint8)),
        depth=to_wire(depth.astype(np.float32)),
        T_base_camera=tuple(T_BASE_CAMERA.ravel().tolist()),
    )
    return frame, labels == 2


def test_a_detection_message_carries_the_bottles_geometry_and_its_mask() -> None:
    frame, mask = _frame()
    found = detect(
        frame, T_WORLD_BASE, [Inst("bottle", 0.9, mask), Inst("can", 0.2, mask)], min_score=0.5
    )
    assert len(found) == 1  # the can scored below min_score
    det = decode(encode(found[0].detection), Detection)  # it travels
    assert det.class_name == "bottle" and det.shape == "cylinder" and not det.axis_fallback
    assert (
        math.hypot(det.axis_in_world[0] - BOTTLE_XY[0], det.axis_in_world[1] - BOTTLE_XY[1]) < 2e-3
    )
    assert det.radius == pytest.approx(0.03, abs=2e-3)
    assert det.d_obj == pytest.approx(math.hypot(*det.centroid_in_base_yaw[:2]))
    assert det.theta_obj == pytest.approx(
        math.atan2(det.centroid_in_base_yaw[1], det.centroid_in_base_yaw[0])
    )
    np.testing.assert_array_equal(mask_of(det, (H, W)), mask)
    # the axis in base_yaw is the world axis seen from the base's heading and position
    c, s = math.cos(0.4), math.sin(0.4)
    dx, dy = det.axis_in_world[0] - 0.5, det.axis_in_world[1] + 0.2
    assert det.axis_in_base_yaw[0] == pytest.approx(c * dx + s * dy, abs=1e-9)
    assert det.axis_in_base_yaw[1] == pytest.approx(-s * dx + c * dy, abs=1e-9)


def test_a_can_read_as_a_box_travels_as_a_can_with_the_networks_class_beside_it() -> None:
    frame, mask = _frame()  # the 3 cm cylinder, 1 m ahead: a can's shape
    check = ShapeCheck(range_m=1.2, rms_per_m2=2.8e-3)
    det = decode(encode(detect(frame, T_WORLD_BASE, [Inst("box", 0.9, mask)], 0.5, check)[0]
                        .detection), Detection)  # fmt: skip
    assert (det.class_name, det.network_class, det.shape) == ("can", "box", "cylinder")
    assert class_text(det) == "can (network: box)"
    same = detect(frame, T_WORLD_BASE, [Inst("can", 0.9, mask)], 0.5, check)[0].detection
    assert (same.class_name, same.network_class, class_text(same)) == ("can", None, "can")
    unchecked = detect(frame, T_WORLD_BASE, [Inst("box", 0.9, mask)], 0.5)[0].detection
    assert (unchecked.class_name, unchecked.network_class) == ("box", None)


def test_a_mask_of_another_size_than_the_depth_is_refused() -> None:
    frame, _ = _frame()
    with pytest.raises(ValueError, match="does not match depth"):
        detect(frame, T_WORLD_BASE, [Inst("bottle", 1.0, np.ones((10, 10), dtype=bool))], 0.5)


def _dets(stamp_ns: int, camera: str, *items: tuple[str, float, int, float]) -> Detections:
    frame, mask = _frame()
    base = detect(frame, T_WORLD_BASE, [Inst("bottle", 1.0, mask)], 0.0)[0].detection
    dets = [
        Detection(
            **{f: getattr(base, f) for f in base.__struct_fields__ if f not in ("class_name",)}
            | {"class_name": c, "score": sc, "n_points": n}
            | {"axis_in_world": (x, 0.0, 0.9), "centroid_in_world": (x - 0.03, 0.0, 0.9)}
        )
        for c, sc, n, x in items
    ]
    return Detections(
        stamp_ns=stamp_ns,
        camera=camera,
        T_world_base=tuple(T_WORLD_BASE.ravel().tolist()),
        segmenter="truth",
        detections=dets,
    )


def test_locate_picks_the_best_scored_fresh_detection_of_a_class() -> None:
    recent = RecentDetections()
    recent.put(_dets(0, "camera_head", ("bottle", 0.99, 100, 1.0)))  # old by the end
    recent.put(_dets(2_000_000_000, "camera_wrist", ("bottle", 0.8, 50, 2.0), ("can", 0.9, 9, 3.0)))
    recent.put(_dets(2_000_000_000, "camera_head", ("bottle", 0.9, 10, 4.0)))
    best = best_of_class(recent.candidates(None, 1.0), "bottle")
    assert best is not None and best[0] == "camera_head" and best[2].axis_in_world[0] == 4.0
    wrist = best_of_class(recent.candidates("camera_wrist", 1.0), "bottle")
    assert wrist is not None and wrist[2].score == 0.8
    assert best_of_class(recent.candidates(None, 1.0), "person") is None


def test_locate_by_position_takes_the_nearest_detection_of_the_class_within_the_gate() -> None:
    recent = RecentDetections()
    recent.put(_dets(0, "camera_head", ("bottle", 0.9, 10, 1.0), ("bottle", 0.9, 10, 1.3)))
    cands = recent.candidates(None, 1.0)
    near = nearest_to(cands, "bottle", (1.25, 0.0), 0.5)
    assert near is not None and near[2].axis_in_world[0] == 1.3
    assert nearest_to(cands, "bottle", (3.0, 0.0), 0.5) is None
    assert nearest_to(cands, "can", (1.0, 0.0), 0.5) is None


@pytest.mark.parametrize(
    ("request_", "words"),
    [
        (None, "needs a LocateRequest"),
        (LocateRequest(), "exactly one"),
        (LocateRequest(class_name="bottle", map_id="bottle_1"), "exactly one"),
        (LocateRequest(class_name="chair"), "classes are"),
        (LocateRequest(class_name="bottle", camera="camera_tail"), "cameras are"),
        (LocateRequest(class_name="bottle", max_age_s=-1.0), "positive"),
    ],
)
def test_locate_requests_that_cannot_be_answered_are_refused_with_the_reason(
    request_: LocateRequest | None, words: str
) -> None:
    with pytest.raises(RequestError, match=words):
        check_request(request_, ["camera_head", "camera_wrist"], CLASSES)
