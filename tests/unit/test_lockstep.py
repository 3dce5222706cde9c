"""The sim's ack bookkeeping: who it must wait for, and when."""

from __future__ import annotations

import pytest

from common.config import Participant
from common.lockstep import AckGate

MS = 1_000_000


def gate() -> AckGate:
    return AckGate(
        {
            "perception": Participant(role="periodic", period_s=0.1, latency_s=0.05),
            "nav": Participant(role="periodic", period_s=0.05, latency_s=0.02),
            "wbc": Participant(role="command", period_s=0.001, latency_s=0.0),
        },
        tick_ns=MS,
    )


def test_a_participant_is_waited_for_only_once_its_output_is_due() -> None:
    g = gate()
    g.join("perception", 0)
    assert g.blocking(49 * MS) == []  # its tick at 0 takes effect at 50 ms
    assert g.blocking(50 * MS) == ["perception"]
    g.ack("perception", 0)
    assert g.blocking(50 * MS) == []
    assert g.blocking(149 * MS) == []
    assert g.blocking(150 * MS) == ["perception"]  # its tick at 100 ms


def test_every_live_participant_is_accounted_for() -> None:
    g = gate()
    g.join("perception", 0)
    g.join("nav", 0)
    assert g.blocking(50 * MS) == ["nav", "perception"]
    g.ack("nav", 0)
    assert g.blocking(50 * MS) == ["perception"]
    assert "wbc" not in g.schedules  # the commander answers states; it has no acks


def test_a_dead_participant_is_not_waited_for() -> None:
    g = gate()
    g.join("perception", 0)
    g.leave("perception")
    assert g.blocking(1000 * MS) == []


def test_a_late_joiner_owes_nothing_before_it_joined() -> None:
    g = gate()
    g.join("perception", 1234 * MS)
    assert g.blocking(1250 * MS) == []  # its tick at 1200 ms was before it joined
    assert g.blocking(1350 * MS) == ["perception"]  # the one at 1300 ms it owes
    g.ack("perception", 1300 * MS)
    assert g.blocking(1350 * MS) == []


def test_a_latency_shorter_than_a_tick_is_refused() -> None:
    with pytest.raises(ValueError, match="shorter than one tick"):
        AckGate({"p": Participant(role="periodic", period_s=0.01, latency_s=0.0)}, tick_ns=MS)


def test_the_clock_goes_out_at_every_participant_boundary() -> None:
    g = gate()
    assert g.clock_due(0, 10 * MS)
    assert g.clock_due(50 * MS, 1000 * MS)
    assert not g.clock_due(51 * MS, 10 * MS)
