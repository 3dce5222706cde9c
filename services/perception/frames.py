"""One camera's `Detections` for one tick: wait for the frame, segment, measure, publish.

`FrameProcessor.process(cam, b)` (the loop's thread only; no lock: nothing here is shared)
waits at most `perception.frame_timeout_s` wall seconds for the camera's frame stamped b
(sim time, ns), for `odom` stamped b (where the robot believes its base was at capture,
with the localization's correction in effect at b: it places what the frame shows in the
map) and, with the `truth` segmenter, for its
`segmentation_truth` stamped b;
segments it (the ONNX network, or the sim's labels), measures each instance
(`pipeline.detect`), drops the people inside the robot, lying flat on the floor or that
are a table's edge (`self_filter.drop_self`) and
publishes `Detections` stamped b whatever happens: an empty list with a `reason` when
nothing could be processed (no frame, no odom, no segmenter, a bad frame, a segmenter
that raised). `process_ms` is the wall time from the frame's arrival to the message,
`segment_ms` the segmenter's. A change of reason is logged once (not every tick), and
so is a change of the classes a camera sees.

No Zenoh: the frames come in as `Latest`-like buffers (`ByStamp`), the network as a
`Network` (`segmenter.Segmenter`), the message goes to `publish`, and
`show(msg, detected, (height, width))` draws a processed frame (rerun).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from common.bus import WaitTimeout
from common.config import PerceptionSettings
from common.geometry import FloatArray, T_of_pose
from common.messages.arrays import ArrayError, as_numpy
from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from common.messages.sim import CameraFrame, Odom, SegmentationTruth
from services.perception.measure import ShapeCheck
from services.perception.pipeline import CLASSES, Detected, Segmented, class_text, detect
from services.perception.segmenter import TruthSegmenter
from services.perception.self_filter import drop_self

log = logging.getLogger("dume.perception")
T = TypeVar("T", CameraFrame, SegmentationTruth, Odom)
M_co = TypeVar("M_co", covariant=True)

#: The base's pose in a `Detections` of a camera whose frame did not come.
IDENTITY = tuple(float(x) for x in (1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1))


def shape_check_of(settings: PerceptionSettings) -> ShapeCheck | None:
    """The can/box shape check the settings ask for (None: `shape_check_range_m` 0)."""
    if settings.shape_check_range_m <= 0.0:
        return None
    return ShapeCheck(settings.shape_check_range_m, settings.shape_check_rms_per_m2)


class ByStamp(Protocol[M_co]):
    """A buffer of one key's messages by stamp (`common.bus.Latest`)."""

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> object: ...

    def at(self, stamp_ns: int) -> M_co | None: ...


class Network(Protocol):
    """The instance segmentation network (`segmenter.Segmenter`)."""

    def segment(
        self, rgb: NDArray[np.uint8], depth: NDArray[np.floating]
    ) -> Sequence[Segmented]: ...


class FrameProcessor:
    """Every camera's detections for a tick (see the module docstring).

    `network` is the ONNX segmenter (None with the `truth` segmenter, or when it cannot
    run: then `unavailable` says why); `truths` holds each camera's `segmentation_truth`
    (used with the `truth` segmenter only); `odom` the robot's base.
    """

    def __init__(
        self,
        settings: PerceptionSettings,
        frames: Mapping[str, ByStamp[CameraFrame]],
        truths: Mapping[str, ByStamp[SegmentationTruth]],
        odom: ByStamp[Odom],
        network: Network | None,
        unavailable: str,
        publish: Callable[[Detections], None],
        show: Callable[[Detections, list[Detected], tuple[int, int]], None],
        place: Callable[[Odom, int], FloatArray] | None = None,
    ) -> None:
        self.settings = settings
        #: The base in the map (4 × 4) of an odom sample at tick b: the localization's
        #: correction composed (`common.map_frame.MapFrame.base`); odom itself without.
        self.place = place or (
            lambda o, _b: T_of_pose(o.base_position_in_world, o.base_orientation_xyzw)
        )
        self.truth = settings.segmenter == "truth"
        self.frames, self.truths, self.odom = frames, truths, odom
        self.network, self.unavailable = network, unavailable
        self.truth_segmenter = TruthSegmenter(CLASSES)
        self.shape_check = None if self.truth else shape_check_of(settings)  # truth is truth
        self.publish, self.show = publish, show
        self._seen: dict[str, tuple[str, ...]] = {}
        self._reasons: dict[str, str] = {}

    def _wait(self, latest: ByStamp[T], b: int, what: str) -> tuple[T | None, str]:
        with contextlib.suppress(WaitTimeout):
            latest.wait_stamp(b, self.settings.frame_timeout_s)
        msg = latest.at(b)
        if msg is None or msg.stamp_ns != b:
            return (
                None,
                f"no {what} stamped {b / NS_PER_S:.3f} s within {self.settings.frame_timeout_s} s",
            )
        return msg, ""

    def process(self, cam: str, b: int) -> None:
        """Detections of `cam` for tick b, published whatever happens (with a reason)."""
        frame, reason = self._wait(self.frames[cam], b, f"{cam} frame")
        odom: Odom | None = None
        if frame is not None:
            odom, reason = self._wait(self.odom, b, "odom")
        t0 = time.perf_counter()  # the frame is in: from here on it is perception's time
        detected: list[Detected] = []
        segment_ms = 0.0
        T_world_base = IDENTITY
        if frame is not None and odom is not None:
            T = self.place(odom, b)
            T_world_base = tuple(T.ravel().tolist())
            try:
                instances, reason, segment_ms = self._segment(cam, frame, b)
                min_score = self.settings.min_score
                detected = (
                    detect(frame, T, instances, min_score, self.shape_check) if not reason else []
                )
                detected, selves = drop_self(detected, frame.width)
                if selves:
                    log.debug("%s at t=%.3f s: %d person(s) in the robot, flat or a slab dropped",
                              cam, b / NS_PER_S, selves)  # fmt: skip
            except (ArrayError, ValueError) as exc:
                reason = f"bad frame: {exc}"
            except Exception as exc:  # a segmenter bug: say so, keep ticking
                log.exception("%s at t=%.3f s: segmentation failed", cam, b / NS_PER_S)
                reason = f"segmentation failed: {type(exc).__name__}: {exc}"
        if reason != self._reasons.get(cam, ""):  # once per change, not every tick
            if reason:
                log.warning("%s at t=%.3f s: %s", cam, b / NS_PER_S, reason)
            else:
                log.info("%s at t=%.3f s: frames processed again", cam, b / NS_PER_S)
            self._reasons[cam] = reason
        msg = Detections(
            stamp_ns=b,
            camera=cam,
            T_world_base=T_world_base,
            segmenter=self.settings.segmenter,
            detections=[d.detection for d in detected],
            reason=reason,
            process_ms=(time.perf_counter() - t0) * 1e3,
            segment_ms=segment_ms,
        )
        self.publish(msg)
        if frame is not None:
            self.show(msg, detected, (frame.height, frame.width))
        self._log_changes(msg)

    def _segment(
        self, cam: str, frame: CameraFrame, b: int
    ) -> tuple[Sequence[Segmented], str, float]:
        """Instances of the frame, the reason when there are none to be had, segment ms."""
        if self.truth:
            truth, reason = self._wait(self.truths[cam], b, f"{cam} segmentation_truth")
            if truth is None:
                return [], reason, 0.0
            t0 = time.perf_counter()
            labels = np.asarray(as_numpy(truth.labels), dtype=np.int32)
            found: Sequence[Segmented] = self.truth_segmenter.segment(labels, truth.instances)
            return found, "", (time.perf_counter() - t0) * 1e3
        if self.network is None:
            return [], self.unavailable or "no segmenter", 0.0
        t0 = time.perf_counter()
        rgb = np.asarray(as_numpy(frame.rgb), dtype=np.uint8)
        depth = np.asarray(as_numpy(frame.depth), dtype=np.float32)
        found = self.network.segment(rgb, depth)
        return found, "", (time.perf_counter() - t0) * 1e3

    def _log_changes(self, msg: Detections) -> None:
        """An info line when what a camera sees changes (classes seen)."""
        seen = tuple(sorted(d.class_name for d in msg.detections))
        if self._seen.get(msg.camera) == seen:
            return
        self._seen[msg.camera] = seen
        items = ", ".join(
            f"{class_text(d)} d={d.d_obj:.2f} m θ={math.degrees(d.theta_obj):+.1f}°"
            for d in msg.detections
        )
        log.info("%s at t=%.3f s sees: %s", msg.camera, msg.stamp_ns / NS_PER_S, items or "nothing")
