"""One camera's detections for a tick, without Zenoh: every tick publishes, with a reason
when nothing could be processed. The frame is the ray-cast bottle on a table of
`test_perception_geometry_pipeline`."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Generic, TypeVar

import msgspec
import numpy as np
import pytest

from common.bus import WaitTimeout
from common.config import PerceptionSettings
from common.geometry import matrix_to_quat_xyzw
from common.messages import to_wire
from common.messages.perception import Detections
from common.messages.sim import CameraFrame, Odom, SegmentationTruth
from services.perception.frames import IDENTITY, FrameProcessor
from services.perception.pipeline import Detected, Segmented
from tests.unit.test_perception_geometry_pipeline import T_WORLD_BASE, Inst, _frame

CAM = "camera_wrist"
B = 300_000_000  # the ray-cast frame's stamp
M = TypeVar("M", CameraFrame, SegmentationTruth, Odom)
#: The base's pose at capture as a `Detections` carries it.
POSE = tuple(T_WORLD_BASE.ravel().tolist())


def odom(stamp_ns: int = B) -> Odom:
    """The robot's odometry at the stamp: the base where the ray-cast frame was taken."""
    return Odom(
        stamp_ns=stamp_ns,
        base_position_in_world=tuple(T_WORLD_BASE[:3, 3].tolist()),
        base_orientation_xyzw=tuple(matrix_to_quat_xyzw(T_WORLD_BASE[:3, :3]).tolist()),
        base_linear_velocity_in_world=(0.0, 0.0, 0.0),
        base_angular_velocity_in_base=(0.0, 0.0, 0.0),
        gripper_angle=0.0,
        gripper_effort=0.0,
    )


class Buffer(Generic[M]):
    """A `Latest` by hand: the newest message stamped at or before the asked time."""

    def __init__(self, *msgs: M) -> None:
        self.msgs: dict[int, M] = {m.stamp_ns: m for m in msgs}

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> object:
        if not any(s >= stamp_ns for s in self.msgs):
            raise WaitTimeout(f"nothing stamped {stamp_ns}")
        return self.msgs[max(self.msgs)]

    def at(self, stamp_ns: int) -> M | None:
        older = [s for s in self.msgs if s <= stamp_ns]
        return self.msgs[max(older)] if older else None


class Network:
    def __init__(self, found: Sequence[Segmented] = (), error: Exception | None = None) -> None:
        self.found, self.error = found, error

    def segment(self, rgb: np.ndarray, depth: np.ndarray) -> Sequence[Segmented]:
        assert rgb.dtype == np.uint8 and depth.dtype == np.float32
        if self.error is not None:
            raise self.error
        return self.found


class Rig:
    def __init__(
        self,
        frames: Buffer[CameraFrame],
        network: Network | None = None,
        truths: Buffer[SegmentationTruth] | None = None,
        unavailable: str = "",
        odoms: Buffer[Odom] | None = None,
    ) -> None:
        settings = PerceptionSettings(
            segmenter="truth" if truths is not None else "network", frame_timeout_s=0.01
        )
        self.published: list[Detections] = []
        self.shown: list[tuple[Detections, list[Detected], tuple[int, int]]] = []
        self.processor = FrameProcessor(
            settings,
            {CAM: frames},
            {CAM: truths} if truths is not None else {},
            odoms if odoms is not None else Buffer(odom()),
            network,
            unavailable,
            self.published.append,
            lambda msg, detected, shape: self.shown.append((msg, detected, shape)),
        )

    def tick(self, b: int = B) -> Detections:
        self.processor.process(CAM, b)
        return self.published[-1]


def test_a_camera_whose_frame_does_not_come_publishes_an_empty_list_with_the_reason() -> None:
    frame, _ = _frame()
    for frames in (Buffer[CameraFrame](), Buffer(frame)):  # none, or only an older one
        rig = Rig(frames, Network())
        msg = rig.tick(B + 100_000_000)
        assert (msg.stamp_ns, msg.camera, msg.detections) == (B + 100_000_000, CAM, [])
        assert msg.reason == f"no {CAM} frame stamped 0.400 s within 0.01 s"
        assert msg.T_world_base == IDENTITY
        assert msg.segmenter == "network"
        assert rig.shown == []


def test_the_networks_instances_are_measured_and_published_with_the_frames_pose() -> None:
    frame, mask = _frame()
    rig = Rig(Buffer(frame), Network([Inst("bottle", 0.9, mask), Inst("can", 0.2, mask)]))
    msg = rig.tick()
    assert [d.class_name for d in msg.detections] == ["bottle"]  # the can scored too low
    assert msg.reason == ""
    np.testing.assert_allclose(msg.T_world_base, POSE, atol=1e-12)  # odom's, at capture
    assert msg.process_ms >= msg.segment_ms >= 0.0
    ((shown, detected, shape),) = rig.shown
    assert shown is msg and len(detected) == 1 and shape == (frame.height, frame.width)


def test_the_truth_segmenter_reads_the_sims_labels_stamped_at_the_tick() -> None:
    frame, mask = _frame()
    labels = to_wire(mask.astype(np.int32))
    truth = SegmentationTruth(stamp_ns=B, camera=CAM, labels=labels, instances={1: "bottle_1"})
    msg = Rig(Buffer(frame), truths=Buffer(truth)).tick()
    assert ([d.class_name for d in msg.detections], msg.segmenter) == (["bottle"], "truth")
    missing = Rig(Buffer(frame), truths=Buffer[SegmentationTruth]()).tick()
    assert missing.detections == []
    assert missing.reason == f"no {CAM} segmentation_truth stamped 0.300 s within 0.01 s"
    np.testing.assert_allclose(missing.T_world_base, POSE, atol=1e-12)  # the frame came


def test_the_shape_check_corrects_the_network_and_never_the_truth_segmenter() -> None:
    frame, mask = _frame()  # a 3 cm cylinder within the check's range
    msg = Rig(Buffer(frame), Network([Inst("box", 0.9, mask)])).tick()
    assert [(d.class_name, d.network_class) for d in msg.detections] == [("can", "box")]
    labels = to_wire(mask.astype(np.int32))
    truth = SegmentationTruth(stamp_ns=B, camera=CAM, labels=labels, instances={1: "box_1"})
    msg = Rig(Buffer(frame), truths=Buffer(truth)).tick()
    assert [(d.class_name, d.network_class) for d in msg.detections] == [("box", None)]


def test_a_frame_without_the_robots_pose_at_capture_is_published_empty_with_why() -> None:
    frame, mask = _frame()
    net = Network([Inst("bottle", 0.9, mask)])
    for odoms in (Buffer[Odom](), Buffer(odom(B - 20_000_000))):  # none, or only an older one
        msg = Rig(Buffer(frame), net, odoms=odoms).tick()
        assert (msg.detections, msg.T_world_base) == ([], IDENTITY)
        assert msg.reason == "no odom stamped 0.300 s within 0.01 s"


@pytest.mark.parametrize(
    ("network", "unavailable", "reason"),
    [
        (None, "segmenter model m.onnx not found", "segmenter model m.onnx not found"),
        (None, "", "no segmenter"),
        (Network(error=RuntimeError("boom")), "", "segmentation failed: RuntimeError: boom"),
        (Network(error=ValueError("odd shape")), "", "bad frame: odd shape"),
    ],
)
def test_a_frame_that_cannot_be_segmented_is_published_empty_with_why(
    network: Network | None, unavailable: str, reason: str
) -> None:
    frame, _ = _frame()
    msg = Rig(Buffer(frame), network, unavailable=unavailable).tick()
    assert (msg.detections, msg.reason) == ([], reason)


def test_a_reason_is_logged_once_per_change(caplog: pytest.LogCaptureFixture) -> None:
    frame, mask = _frame()
    ticks = [B + k * 100_000_000 for k in range(4)]
    frames = Buffer(*(msgspec.structs.replace(frame, stamp_ns=b) for b in ticks))
    rig = Rig(frames, None, unavailable="no model", odoms=Buffer(*(odom(b) for b in ticks)))
    with caplog.at_level(logging.INFO, logger="dume.perception"):
        for b in ticks[:3]:
            rig.tick(b)
        rig.processor.network = Network([Inst("bottle", 0.9, mask)])
        rig.tick(ticks[3])
    assert [r.getMessage() for r in caplog.records] == [
        f"{CAM} at t=0.300 s: no model",
        f"{CAM} at t=0.300 s sees: nothing",
        f"{CAM} at t=0.600 s: frames processed again",
        f"{CAM} at t=0.600 s sees: bottle d=0.98 m θ=+5.7°",
    ]
