"""The perception service: a lockstep participant at the camera rate.

For each tick b (`PeriodicTicker`), for each camera: wait for its frame stamped b (and,
with the `truth` segmenter, its `segmentation_truth` stamped b), segment, measure each
instance (`pipeline.detect`), publish `Detections` stamped b — every tick and every
camera, an empty list with a `reason` when nothing could be processed — then ack b.
`perception/locate` answers from the newest detections (`locate`). The segmenter is the
ONNX network by default; `perception.segmenter="truth"` reads the sim's labels instead,
for ablation and evaluation only, and every `Detections` says which one ran.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Sequence
from typing import TypeVar

import msgspec
import numpy as np

from common.bus import Latest, NoReply, RemoteError, RequestError, WaitTimeout
from common.config import ConfigError, PerceptionSettings, resolve
from common.keys import map_artifact, map_person
from common.lockstep import PeriodicTicker
from common.messages.arrays import ArrayError, as_numpy
from common.messages.base import NS_PER_S
from common.messages.perception import Detections, LocateReply, LocateRequest
from common.messages.semantic_map import MapEntity
from common.messages.sim import CameraFrame, SegmentationTruth
from common.service import Service
from services.perception.locate import (
    RecentDetections,
    best_of_class,
    check_request,
    nearest_to,
)
from services.perception.perception_log import PerceptionLogger
from services.perception.pipeline import CLASSES, Detected, Segmented, detect
from services.perception.segmenter import Segmenter, SegmenterError, TruthSegmenter
from services.perception.self_filter import drop_self

NAME = "perception"
log = logging.getLogger(f"dume.{NAME}")
T = TypeVar("T", CameraFrame, SegmentationTruth)


def load_network(settings: PerceptionSettings) -> tuple[Segmenter | None, str]:
    """The ONNX segmenter, or None and the reason it cannot run."""
    path = resolve(settings.model)
    if not path.exists():
        return None, (
            f"segmenter model {settings.model} not found: train it (`dume train-segmenter`) or "
            'evaluate with --set perception.segmenter="truth"'
        )
    try:
        return Segmenter(path, threads=settings.dnn_threads or None), ""
    except SegmenterError as exc:
        return None, f"network segmenter cannot start: {exc}"


class PerceptionNode:
    def __init__(self, svc: Service) -> None:
        self.svc = svc
        cfg = svc.config
        self.settings = cfg.perception
        self.period_ns = cfg.time.period_ns_of(NAME, 1.0 / cfg.sim.camera_hz)
        camera_ns = round(NS_PER_S / cfg.sim.camera_hz)
        if self.period_ns % camera_ns:
            raise ConfigError(
                f"perception's period {self.period_ns / NS_PER_S} s is not a multiple of the "
                f"cameras' {camera_ns / NS_PER_S} s: it would wait for frames that never come"
            )
        self.cameras = [c for c in self.settings.cameras if c in cfg.sim.cameras]
        self.truth = self.settings.segmenter == "truth"
        self.network: Segmenter | None = None
        self.truth_segmenter = TruthSegmenter(CLASSES)
        self.unavailable = ""
        if self.truth:
            log.warning("segmenter: truth (the sim's labels) — ablation and evaluation only")
        else:
            self.network, self.unavailable = load_network(self.settings)
            if self.unavailable:
                log.error("%s: publishing empty detections with this reason", self.unavailable)
        bus, keys = svc.bus, svc.keys
        self.frames = {
            c: bus.latest(keys.camera_rgbd(c), CameraFrame, history=4) for c in self.cameras
        }
        self.truths = (
            {
                c: bus.latest(keys.camera_segmentation_truth(c), SegmentationTruth, history=4)
                for c in self.cameras
            }
            if self.truth
            else {}
        )
        self.publisher = bus.publisher(keys.detections, Detections, "data")
        self.recent = RecentDetections()
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_ns / NS_PER_S, svc.stop)
        self.logger = PerceptionLogger(svc.rec, cfg.recording.depth_every)
        self._seen: dict[str, tuple[str, ...]] = {}
        self._reasons: dict[str, str] = {}
        bus.serve(keys.locate, LocateRequest, self._locate)

    # -- the loop -------------------------------------------------------------------------

    def run(self) -> None:
        self.svc.ready()
        log.info(
            "cameras %s every %.3f s, segmenter %s",
            self.cameras,
            self.period_ns / NS_PER_S,
            self.settings.segmenter,
        )
        for b in self.ticker.ticks():
            for cam in self.cameras:
                self._process(cam, b)
            self.ticker.ack(b)

    def _wait(self, latest: Latest[T], b: int, what: str) -> tuple[T | None, str]:
        with contextlib.suppress(WaitTimeout):
            latest.wait_stamp(b, self.settings.frame_timeout_s)
        msg = latest.at(b)
        if msg is None or msg.stamp_ns != b:
            return (
                None,
                f"no {what} stamped {b / NS_PER_S:.3f} s within {self.settings.frame_timeout_s} s",
            )
        return msg, ""

    def _process(self, cam: str, b: int) -> None:
        """Detections of `cam` for tick b, published whatever happens (with a reason)."""
        frame, reason = self._wait(self.frames[cam], b, f"{cam} frame")
        t0 = time.perf_counter()  # the frame is in: from here on it is perception's time
        detected: list[Detected] = []
        segment_ms = 0.0
        if frame is not None:
            try:
                instances, reason, segment_ms = self._segment(cam, frame, b)
                detected = detect(frame, instances, self.settings.min_score) if not reason else []
                detected, selves = drop_self(detected)
                if selves:
                    log.debug("%s at t=%.3f s: %d person(s) inside the robot dropped",
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
            T_world_base=frame.T_world_base if frame is not None else _IDENTITY,
            segmenter=self.settings.segmenter,
            detections=[d.detection for d in detected],
            reason=reason,
            process_ms=(time.perf_counter() - t0) * 1e3,
            segment_ms=segment_ms,
        )
        self.publisher.put(msg)
        self.recent.put(msg)
        if frame is not None:
            self.logger.frame(msg, detected, (frame.height, frame.width))
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
            found = self.truth_segmenter.segment(labels, truth.instances)
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
            f"{d.class_name} d={d.d_obj:.2f} m θ={math.degrees(d.theta_obj):+.1f}°"
            for d in msg.detections
        )
        log.info("%s at t=%.3f s sees: %s", msg.camera, msg.stamp_ns / NS_PER_S, items or "nothing")

    # -- locate ---------------------------------------------------------------------------

    def _locate(self, req: LocateRequest | None, selector: str) -> LocateReply:
        del selector
        req = check_request(req, self.cameras, CLASSES)
        if self.unavailable:
            raise RequestError("unavailable", self.unavailable)
        if self.recent.now_ns < 0:
            raise RequestError("unavailable", "no frame processed yet")
        cands = self.recent.candidates(req.camera, req.max_age_s)
        if req.class_name is not None:
            best = best_of_class(cands, req.class_name)
        else:
            assert req.map_id is not None  # check_request: exactly one
            entity = self._map_entity(req.map_id)
            best = nearest_to(
                cands, entity.class_name, entity.position_in_world[:2], self.settings.locate_gate_m
            )
            if best is not None:
                best = (best[0], best[1], msgspec.structs.replace(best[2], map_id=req.map_id))
        if best is None:
            return LocateReply(stamp_ns=self.recent.now_ns, found=False)
        return LocateReply(stamp_ns=best[1], found=True, camera=best[0], detection=best[2])

    def _map_entity(self, map_id: str) -> MapEntity:
        key = map_person(map_id) if map_id.startswith("person_") else map_artifact(map_id)
        try:
            return self.svc.bus.query(key, None, MapEntity, timeout_s=1.0)
        except NoReply:
            raise RequestError(
                "unavailable", f"the semantic map does not answer {key}: cannot locate by map id"
            ) from None
        except RemoteError as exc:
            raise RequestError(exc.error.code, exc.error.message) from None


_IDENTITY = tuple(float(x) for x in (1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1))


def main(svc: Service) -> None:
    PerceptionNode(svc).run()
