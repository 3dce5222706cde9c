"""The map's intake (`services.semantic_map.intake`) on fake subscriptions: detections
are kept per stamp and camera, released for fusion in stamp order once due, and at a
perception tick only when every fused camera's frame due then is in (bounded); the wrist
camera is fused while the mission's patrol status says it holds the arm in `look`."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pytest

from common.bus import WaitTimeout
from common.lockstep import Schedule
from common.messages.mission import PatrolStatus
from common.messages.perception import Detections
from common.messages.sim import CameraFrame
from services.semantic_map.intake import (
    DetectionIntake,
    fused_cameras,
    patrol_holds_look,
    perception_due,
)

MS = 1_000_000
PERIOD = 100 * MS
EYE = tuple(np.eye(4).ravel().tolist())
CAMS = ["head", "wrist"]


def _dets(camera: str, stamp_ns: int) -> Detections:
    return Detections(
        stamp_ns=stamp_ns, camera=camera, T_world_base=EYE, segmenter="truth", detections=[]
    )


class FakeFifo:
    """`queued` is in at once; `late` arrives one by one, only to a `pop` that waits."""

    def __init__(self, *queued: Detections) -> None:
        self.queued: deque[Detections] = deque(queued)
        self.late: deque[Detections] = deque()
        self.waits: list[float] = []

    def drain(self) -> Iterator[Detections]:
        while self.queued:
            yield self.queued.popleft()

    def pop(self, timeout_s: float = 0.0) -> Detections | None:
        self.waits.append(timeout_s)
        if self.queued:
            return self.queued.popleft()
        if timeout_s > 0 and self.late:
            return self.late.popleft()
        return None


def _released(intake: DetectionIntake, *args: object) -> list[tuple[str, int]]:
    return [(d.camera, d.stamp_ns) for d in intake.release(*args)]  # type: ignore[arg-type]


def test_frames_are_released_only_when_every_fused_cameras_frame_due_is_in() -> None:
    fifo = FakeFifo(_dets("head", 0), _dets("wrist", 0), _dets("head", PERIOD))
    fifo.late.extend([_dets("head", 2 * PERIOD), _dets("wrist", PERIOD)])
    intake = DetectionIntake(fifo, {})
    # at the tick whose due stamp is PERIOD, the wrist camera's frame is not in yet: it is
    # waited for (the head camera's next frame, arriving first, is kept for later)
    got = _released(intake, 2 * PERIOD, CAMS, PERIOD, PERIOD)
    assert got == [("head", 0), ("wrist", 0), ("head", PERIOD), ("wrist", PERIOD)]
    assert fifo.waits and all(w > 0 for w in fifo.waits)
    assert list(intake.pending) == [2 * PERIOD]
    assert _released(intake, 3 * PERIOD, CAMS, 2 * PERIOD, None) == [("head", 2 * PERIOD)]
    assert not intake.pending


def test_a_due_frame_that_never_comes_is_waited_for_bounded_then_fused_without(
    caplog: pytest.LogCaptureFixture,
) -> None:
    fifo = FakeFifo(_dets("head", PERIOD))
    intake = DetectionIntake(fifo, {}, wait_s=0.05)
    with caplog.at_level(logging.WARNING, logger="dume.semantic_map"):
        got = _released(intake, 2 * PERIOD, CAMS, PERIOD, PERIOD)
    assert got == [("head", PERIOD)]
    assert "detections at 100000000 missing" in caplog.text
    # the late frame is fused at the next tick (its stamp is due)
    fifo.queued.append(_dets("wrist", PERIOD))
    assert _released(intake, 3 * PERIOD, CAMS, 2 * PERIOD, None) == [("wrist", PERIOD)]


def test_nothing_is_waited_for_off_perceptions_ticks_in_realtime_or_before_zero() -> None:
    for due, period in ((PERIOD + 50 * MS, PERIOD), (PERIOD, None), (-PERIOD, PERIOD)):
        fifo = FakeFifo(_dets("head", 0))
        fifo.late.append(_dets("wrist", 0))
        intake = DetectionIntake(fifo, {})
        assert _released(intake, 2 * PERIOD, CAMS, due, period) == (
            [("head", 0)] if due >= 0 else []
        )
        assert not fifo.waits and len(fifo.late) == 1  # nothing waited for


def test_only_fused_cameras_are_kept_and_released_in_their_order() -> None:
    fifo = FakeFifo(_dets("wrist", 0), _dets("head", 0), _dets("tail", 0), _dets("head", PERIOD))
    intake = DetectionIntake(fifo, {})
    got = _released(intake, PERIOD, ["head", "wrist"], 0, PERIOD)
    assert got == [("head", 0), ("wrist", 0)]
    assert set(intake.pending) == {PERIOD}
    assert set(intake.pending[PERIOD]) == {"head"}


def test_the_wrist_camera_is_fused_only_while_a_patrol_holds_the_arm_up() -> None:
    assert fused_cameras(["head"], ["wrist", "head"], arm_up=False) == ["head"]
    assert fused_cameras(["head"], ["wrist", "head"], arm_up=True) == ["head", "wrist"]


def test_the_missions_patrol_status_says_when_the_arm_is_up() -> None:
    assert not patrol_holds_look(None)  # no mission, or nothing from it yet
    assert patrol_holds_look(PatrolStatus(stamp_ns=0, state="running", arm_look=True))
    assert not patrol_holds_look(PatrolStatus(stamp_ns=0, state="running", arm_look=False))
    # a fetch's search holds the arm up with no job running: the mission says so too
    assert patrol_holds_look(PatrolStatus(stamp_ns=0, state="idle", arm_look=True))


def test_perception_is_waited_for_only_as_a_live_periodic_producer_in_lockstep() -> None:
    def gate(alive: set[str], lockstep: bool, scheduled: bool = True) -> SimpleNamespace:
        schedules = {"perception": Schedule(PERIOD, PERIOD)} if scheduled else {}
        return SimpleNamespace(
            gate=SimpleNamespace(schedules=schedules, alive=alive),
            lockstep=lockstep,
            latency_ns=lambda p: schedules[p].latency_ns if p in schedules else 0,
        )

    b = 5 * PERIOD
    assert perception_due(b, gate({"perception"}, True)) == (4 * PERIOD, PERIOD)  # type: ignore[arg-type]
    assert perception_due(b, gate(set(), True)) == (4 * PERIOD, None)  # type: ignore[arg-type]
    assert perception_due(b, gate({"perception"}, False)) == (4 * PERIOD, None)  # type: ignore[arg-type]
    assert perception_due(b, gate(set(), True, scheduled=False)) == (b, None)  # type: ignore[arg-type]


class FakeFrames:
    def __init__(self, *frames: CameraFrame, arrives: CameraFrame | None = None) -> None:
        self.frames = list(frames)
        self.arrives = arrives
        self.received = len(frames)

    def at(self, stamp_ns: int) -> CameraFrame | None:
        return next((f for f in reversed(self.frames) if f.stamp_ns <= stamp_ns), None)

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CameraFrame:
        if self.arrives is None or self.arrives.stamp_ns < stamp_ns:
            raise WaitTimeout("no frame")
        self.frames.append(self.arrives)
        return self.arrives


def _frame(stamp_ns: int) -> CameraFrame:
    return SimpleNamespace(stamp_ns=stamp_ns)  # type: ignore[return-value]


def test_the_frame_behind_detections_is_the_one_of_their_stamp_or_none() -> None:
    old, due = _frame(0), _frame(PERIOD)
    intake = DetectionIntake(
        FakeFifo(), {"head": FakeFrames(old, arrives=due), "wrist": FakeFrames()}
    )
    assert intake.frame("head", PERIOD) is due  # waited for
    assert intake.frame("head", 0) is old
    assert intake.frame("wrist", PERIOD) is None  # nothing ever received
    assert intake.frame("tail", PERIOD) is None  # not subscribed
    assert intake.frame("head", 3 * PERIOD) is None  # never comes: fused without
