"""The perception service: a lockstep participant at the camera rate.

For each tick b (`PeriodicTicker`), for each camera: wait for its frame stamped b (and,
with the `truth` segmenter, its `segmentation_truth` stamped b), segment, measure each
instance (`pipeline.detect`), publish `Detections` stamped b — every tick and every
camera, an empty list with a `reason` when nothing could be processed — then ack b.
`perception/locate` answers from the newest detections (`locate`). The segmenter is the
ONNX network by default; `perception.segmenter="truth"` reads the sim's labels instead,
for ablation and evaluation only, and every `Detections` says which one ran.

This module is wiring only: a camera's work for a tick is `frames.FrameProcessor`'s, the
queryable's `locator.Locator`'s.
"""

from __future__ import annotations

import logging

from common.config import ConfigError, PerceptionSettings, resolve
from common.geometry import FloatArray
from common.lockstep import PeriodicTicker
from common.map_frame import MapFrame
from common.messages.base import NS_PER_S
from common.messages.perception import Detections, LocateRequest
from common.messages.semantic_map import MapEntity
from common.messages.sim import CameraFrame, Odom, SegmentationTruth
from common.recording import FrameSelector
from common.service import Service
from services.perception.frames import FrameProcessor
from services.perception.locate import RecentDetections
from services.perception.locator import Locator
from services.perception.perception_log import PerceptionLogger
from services.perception.segmenter import Segmenter, SegmenterError

NAME = "perception"
log = logging.getLogger(f"dume.{NAME}")


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
    """The parts, wired from the config and the bus, and the loop; see the module docstring."""

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
        truth = self.settings.segmenter == "truth"
        network: Segmenter | None = None
        unavailable = ""
        if truth:
            log.warning("segmenter: truth (the sim's labels) — ablation and evaluation only")
        else:
            network, unavailable = load_network(self.settings)
            if unavailable:
                log.error("%s: publishing empty detections with this reason", unavailable)
        bus, keys = svc.bus, svc.keys
        frames = {c: bus.latest(keys.camera_rgbd(c), CameraFrame, history=4) for c in self.cameras}
        truths = (
            {
                c: bus.latest(keys.camera_segmentation_truth(c), SegmentationTruth, history=4)
                for c in self.cameras
            }
            if truth
            else {}
        )
        odom = bus.latest(keys.odom, Odom, history=16)
        self.publisher = bus.publisher(keys.detections, Detections, "data", again=True)
        self.recent = RecentDetections()
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_ns / NS_PER_S, svc.stop)
        logger = PerceptionLogger(svc.rec, FrameSelector.of(cfg))
        self.processor = FrameProcessor(
            self.settings, frames, truths, odom, network, unavailable, self._publish, logger.frame,
            self._place,
        )  # fmt: skip
        self.map_frame = MapFrame(bus, keys, cfg)
        self.locator = Locator(
            self.recent,
            self.cameras,
            unavailable,
            self.settings.locate_gate_m,
            lambda key: bus.query(key, None, MapEntity, timeout_s=1.0),
        )
        bus.serve(keys.locate, LocateRequest, self.locator.serve)

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
                self.processor.process(cam, b)
            self.ticker.ack(b)

    def _place(self, odom: Odom, b: int) -> FloatArray:
        """The base at tick b in the map: odom with the localization due at b."""
        if not self.map_frame.wait(b, self.settings.frame_timeout_s):
            log.warning("no localization due at t=%.2f s: the last correction", b / NS_PER_S)
        return self.map_frame.base(odom, b)

    def _publish(self, msg: Detections) -> None:
        """A camera's detections out on the bus, and kept for `locate`."""
        self.publisher.put(msg)
        self.recent.put(msg)


def main(svc: Service) -> None:
    PerceptionNode(svc).run()
