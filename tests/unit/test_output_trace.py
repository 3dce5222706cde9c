"""`common.bus.OutputTrace`: a publisher's running digest, logged on sim-time boundaries."""

from __future__ import annotations

import logging

import pytest

from common.bus import OutputTrace

MS = 1_000_000


def _lines(caplog: pytest.LogCaptureFixture, payloads: list[tuple[bytes, int]]) -> list[str]:
    caplog.clear()
    trace = OutputTrace("dume/b1/odom", 100 * MS)
    with caplog.at_level(logging.INFO, logger="common.bus"):
        for payload, stamp in payloads:
            trace.add(payload, stamp)
    return [r.getMessage() for r in caplog.records]


def test_the_same_outputs_log_the_same_lines_and_one_change_shows_from_its_period(
    caplog: pytest.LogCaptureFixture,
) -> None:
    run = [(f"odom {t}".encode(), t * 20 * MS) for t in range(16)]  # 50 Hz for 0.3 s
    same = _lines(caplog, run)
    assert same == _lines(caplog, list(run))
    assert len(same) == 3 and same[0].startswith("trace dume/b1/odom before t=0.100 s: 5 sent")
    changed = list(run)
    changed[7] = (b"odom moved", changed[7][1])  # t = 0.14 s
    other = _lines(caplog, changed)
    assert other[0] == same[0]  # before the change: the same
    assert other[1:] != same[1:]  # from its period on: not


def test_a_trace_leaves_out_the_wall_clock_fields_and_nothing_else() -> None:
    from common.bus import _traced
    from common.messages import encode
    from common.messages.sim import Clock

    def traced(msg: Clock) -> bytes:
        return _traced(msg, encode(msg))

    fast = Clock(stamp_ns=MS, tick=1, mode="lockstep", rtf=2.0)
    slow = Clock(stamp_ns=MS, tick=1, mode="lockstep", rtf=0.4)
    assert encode(fast) != encode(slow) and traced(fast) == traced(slow)
    assert traced(fast) != traced(Clock(stamp_ns=MS, tick=2, mode="lockstep", rtf=2.0))
