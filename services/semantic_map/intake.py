"""Detections in, released for fusion when due: the map's intake of perception's frames.

One detections key carries every camera's frames (`Detections`, one per camera and
perception tick, stamped with the tick in sim ns). `DetectionIntake.release(b, cameras,
due_ns, period_ns)` keeps the detections of the cameras fused now (`cameras`; any
other's are dropped as they are taken in) per stamp, and hands back, in stamp order and
then in the order of `cameras`, every frame stamped at or before `due_ns` (b −
perception's latency); later ones wait for a later tick. When `period_ns` is given
(perception is a live lockstep producer) and `due_ns` is one of its ticks, it first
waits, at most `wait_s` wall seconds in all, until every fused camera's frame at
`due_ns` is in: the gate may have been met by another camera's message, and older
stamps are complete (one key keeps its order). `frame(cam, s)` is the camera image
behind detections stamped s (waited for, bounded; None without one). Which cameras are
fused is `fused_cameras`: the wrist camera joins while the mission's patrol says it
holds the arm in `look` (`patrol_holds_look`), which the map learns from the mission's
patrol status, not from driving anything.

Only the map's tick thread calls it, with the map's lock held; it takes no lock of its
own (the subscriptions it reads have theirs). It needs no bus: any `DetectionSource` and
`FrameSource` will do (the node passes its Zenoh subscriptions).
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from collections.abc import Iterator, Mapping
from typing import Protocol

from common.bus import WaitTimeout
from common.lockstep import UpstreamGate
from common.messages.base import NS_PER_S
from common.messages.mission import PatrolStatus
from common.messages.perception import Detections
from common.messages.sim import CameraFrame

#: Wall seconds a tick waits for a due camera's detections (the other camera's are in),
#: or for the frame behind detections it fuses.
FRAME_WAIT_S = 2.0
log = logging.getLogger("dume.semantic_map")


class DetectionSource(Protocol):
    """Detections in arrival order (`common.bus.Fifo`)."""

    def drain(self) -> Iterator[Detections]: ...
    def pop(self, timeout_s: float = 0.0) -> Detections | None: ...


class FrameSource(Protocol):
    """One camera's recent frames (`common.bus.Latest`)."""

    @property
    def received(self) -> int: ...
    def at(self, stamp_ns: int) -> CameraFrame | None: ...
    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CameraFrame: ...


def fused_cameras(cameras: list[str], patrol_cameras: list[str], arm_up: bool) -> list[str]:
    """The cameras fused now: `cameras`, and `patrol_cameras` while a patrol holds the
    arm in `look` (the wrist camera then sees bench tops; stowed, it sees the legs)."""
    extra = patrol_cameras if arm_up else []
    return [*cameras, *(c for c in extra if c not in cameras)]


def patrol_holds_look(status: PatrolStatus | None) -> bool:
    """Whether the mission's patrol status (`mission/patrol/status`) says the arm is held
    in `look` to map (a running patrol's, or a fetch's search; None: no status, no)."""
    return status is not None and status.arm_look


def perception_due(b: int, gate: UpstreamGate) -> tuple[int, int | None]:
    """`release`'s `due_ns` and `period_ns` at the tick b: perception's output that takes
    effect by b (b − its latency), and its period when it is a live periodic producer in
    lockstep (else None: nothing is waited for)."""
    schedule = gate.gate.schedules.get("perception")
    live = schedule is not None and "perception" in gate.gate.alive and gate.lockstep
    return b - gate.latency_ns("perception"), (
        schedule.period_ns if live and schedule is not None else None
    )


class DetectionIntake:
    """Detections kept per stamp and camera until due; see the module docstring."""

    def __init__(
        self,
        detections: DetectionSource,
        frames: Mapping[str, FrameSource],
        wait_s: float = FRAME_WAIT_S,
    ) -> None:
        self.detections = detections
        self.frames = frames
        self.wait_s = wait_s
        #: Stamp → camera → its detections, not yet due.
        self.pending: dict[int, dict[str, Detections]] = defaultdict(dict)

    def _collect(self, cameras: list[str]) -> None:
        for dets in self.detections.drain():
            if dets.camera in cameras:
                self.pending[dets.stamp_ns][dets.camera] = dets

    def release(
        self, b: int, cameras: list[str], due_ns: int, period_ns: int | None
    ) -> list[Detections]:
        """The detections due at the tick b, to fuse in this order (module docstring)."""
        self._collect(cameras)
        if period_ns is not None and due_ns >= 0 and due_ns % period_ns == 0:
            deadline = time.monotonic() + self.wait_s
            while not set(cameras) <= set(self.pending.get(due_ns, {})):
                left = deadline - time.monotonic()
                dets = self.detections.pop(timeout_s=left) if left > 0 else None
                if dets is None:
                    log.warning("tick %.1f s: detections at %d missing", b / NS_PER_S, due_ns)
                    break
                if dets.camera in cameras:
                    self.pending[dets.stamp_ns][dets.camera] = dets
        released: list[Detections] = []
        for s in sorted(self.pending):
            if s > due_ns:
                break
            cams = self.pending.pop(s)
            released.extend(cams[cam] for cam in cameras if cam in cams)
        return released

    def frame(self, cam: str, s: int) -> CameraFrame | None:
        """Camera `cam`'s frame stamped `s` (waited for, bounded), None without one."""
        sub = self.frames.get(cam)
        if sub is None or sub.received == 0:
            return None
        frame = sub.at(s)
        if frame is None or frame.stamp_ns != s:
            try:
                sub.wait_stamp(s, self.wait_s)
            except WaitTimeout:
                log.warning("no %s frame stamped %.3f s: detections fused without it", cam, s / 1e9)
                return None
            frame = sub.at(s)
        return frame if frame is not None and frame.stamp_ns == s else None
