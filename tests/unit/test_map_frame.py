"""MapFrame: the correction due at a time, and a plan brought back to odom with the
correction that placed it (the mission's grasps), not the newest."""

from __future__ import annotations

import time
from collections import deque
from typing import Any

import numpy as np

from common.bus import WaitTimeout
from common.config import load_config
from common.geometry import make_T, rot_z
from common.keys import RobotKeys
from common.map_frame import MapFrame
from common.messages.localization import Localization


class FakeLatest:
    def __init__(self, history: int) -> None:
        self.buf: deque[Localization] = deque(maxlen=history)

    def at(self, stamp_ns: int) -> Localization | None:
        return next((m for m in reversed(self.buf) if m.stamp_ns <= stamp_ns), None)

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> None:
        if not any(m.stamp_ns >= stamp_ns for m in self.buf):
            time.sleep(timeout_s)
            raise WaitTimeout(f"nothing at {stamp_ns}")


class FakeWatch:
    def __init__(self) -> None:
        self.now: set[str] = set()

    def alive(self) -> set[str]:
        return set(self.now)


class FakeBus:
    def __init__(self) -> None:
        self.latest_made: FakeLatest | None = None
        self.watch = FakeWatch()

    def latest(self, key: str, type_: Any, history: int = 1) -> FakeLatest:
        self.latest_made = FakeLatest(history)
        return self.latest_made

    def watch_alive(self, key: str) -> FakeWatch:
        return self.watch


def correction(stamp_ns: int, x: float) -> Localization:
    return Localization(stamp_ns, (x, 0.0, 0.0), (x, 0.0, 0.0), (0.0,) * 9, "ok", 1.0)


def estimating_frame(history: int) -> tuple[MapFrame, FakeLatest]:
    participant = {"role": "periodic", "period_s": 0.1, "latency_s": 0.0}
    cfg = load_config({"time.participants.localization": participant}, env={})
    bus = FakeBus()
    frame = MapFrame(bus, RobotKeys("b1"), cfg, history=history)  # type: ignore[arg-type]
    assert frame.enabled and bus.latest_made is not None
    return frame, bus.latest_made


def test_a_wait_ends_when_a_localization_seen_alive_is_gone() -> None:
    """A stopped localization (its token gone, its process still there) once made
    navigation wait its whole timeout at every tick; before it was ever seen alive (the
    stack starting), the wait is as before."""
    participant = {"role": "periodic", "period_s": 0.1, "latency_s": 0.0}
    cfg = load_config({"time.participants.localization": participant,
                       "time.mode": "lockstep"}, env={})  # fmt: skip
    bus = FakeBus()
    frame = MapFrame(bus, RobotKeys("b1"), cfg)  # type: ignore[arg-type]
    t0 = time.perf_counter()
    assert not frame.wait(200_000_000, 0.3)  # never alive: waited its timeout
    assert time.perf_counter() - t0 >= 0.25
    bus.watch.now = {RobotKeys("b1").alive("localization")}
    assert not frame.gone()
    bus.watch.now = set()
    t0 = time.perf_counter()
    assert not frame.wait(300_000_000, 5.0)  # gone: no wait
    assert time.perf_counter() - t0 < 0.5 and frame.gone()


def test_correction_due_at_a_time_and_identity_before_the_first() -> None:
    frame, latest = estimating_frame(64)
    assert np.allclose(frame.map_odom(50_000_000), np.eye(4))
    latest.buf.extend(correction(k * 100_000_000, 0.01 * k) for k in range(10))
    assert frame.map_odom(450_000_000)[0, 3] == 0.04  # tick 0.4 s is due at 0.45 s


def test_a_plan_goes_to_odom_with_the_correction_at_its_capture() -> None:
    frame, latest = estimating_frame(64)
    # the localization moved odom 3 cm between the capture (1.0 s) and now (3.0 s)
    latest.buf.extend(correction(k * 100_000_000, 0.0 if k <= 10 else 0.03) for k in range(31))
    H_map = make_T(rot_z(0.3), (2.0, 1.0, 0.5))
    H_odom = frame.to_odom(H_map, 1_000_000_000, 3_000_000_000)
    assert np.allclose(H_odom, H_map)  # as seen from odom at the capture
    assert np.isclose(frame.to_odom(H_map, 2_000_000_000, 3_000_000_000)[0, 3], 1.97)


def test_a_capture_older_than_what_is_kept_uses_the_newest() -> None:
    frame, latest = estimating_frame(5)
    latest.buf.extend(correction(k * 100_000_000, 0.01 * k) for k in range(30))
    H = frame.to_odom(np.eye(4), 100_000_000, 3_000_000_000)
    assert np.isclose(H[0, 3], -0.29)
