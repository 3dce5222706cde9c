"""A sim clock that jumps, on a real Zenoh session: a periodic participant's ticks stay
strictly increasing. A clock back in time (a stale sample, or a world restarted under a
running stack, which the policy refuses) is waited out, never ticked twice; a clock
that leaps ahead is one tick at the new stamp, never a storm of missed ones.

No service reads the wall clock for its timing (`time.monotonic` only), so a host
clock set back or ahead changes nothing but log stamps."""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path

import pytest

from common.bus import Bus
from common.keys import WORLD_CLOCK, RobotKeys
from common.lockstep import PeriodicTicker
from common.messages.sim import Clock
from tests.integration.peers import loopback_peer

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]


_session = loopback_peer


def test_ticks_stay_increasing_through_a_clock_that_jumps_back_and_ahead() -> None:
    with _session() as s:
        bus = Bus(s)
        stop = threading.Event()
        ticker = PeriodicTicker(bus, RobotKeys("b1"), "jumpy", 0.05, stop)
        clock = bus.publisher(WORLD_CLOCK, Clock, "control")
        seen: list[int] = []
        idles = [0]

        def follow() -> None:
            for b in ticker.ticks(poll_s=0.02, on_idle=lambda: idles.__setitem__(0, idles[0] + 1)):
                seen.append(b)
                ticker.ack(b)

        def settle(n: int, idle0: int, ticks: bool) -> None:
            """Until the ticker ticked once more than `n`, or (no tick due) idled twice
            since `idle0` (both taken before the clock went out)."""
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                if len(seen) > n or (not ticks and idles[0] >= idle0 + 2):
                    return
                time.sleep(0.005)

        thread = threading.Thread(target=follow, daemon=True)
        thread.start()
        while idles[0] < 2:  # it waits for a clock
            time.sleep(0.005)
        ms = 1_000_000
        steps = ((50, True), (100, True), (150, True), (20, False), (60, False), (120, False),
                 (100_000, True), (200, False), (100_050, True))  # fmt: skip
        for t_ms, ticks in steps:
            n, idle0 = len(seen), idles[0]
            clock.put(Clock(stamp_ns=t_ms * ms, tick=t_ms, mode="lockstep"))
            settle(n, idle0, ticks)
        stop.set()
        thread.join(2.0)
        assert seen == [50 * ms, 100 * ms, 150 * ms, 100_000 * ms, 100_050 * ms]


def test_no_service_times_itself_by_the_wall_clock() -> None:
    """`time.time()` / `datetime.now()` nowhere in the services or `common`, but the
    certificates' validity (a date)."""
    found = {
        str(p.relative_to(REPO))
        for top in ("services", "common")
        for p in sorted((REPO / top).rglob("*.py"))
        if re.search(r"\btime\.time(_ns)?\(|datetime\.(datetime\.)?now\(", p.read_text())
    }
    assert found == {"common/certs.py"}, found
