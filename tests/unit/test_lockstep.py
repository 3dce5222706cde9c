"""The sim's half of lockstep: its ack bookkeeping (who it must wait for, and when) and its
waits (the start gate, acks, commands, stalls, liveliness), without Zenoh."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Generic, Literal, TypeVar

import pytest

from common.bus import WaitTimeout
from common.config import Participant, TimeSettings
from common.keys import RobotKeys
from common.lockstep import AckGate, SimGate
from common.messages.sim import Ack

T = TypeVar("T")

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


# -- the sim's side (`SimGate`), with fakes for Zenoh's inboxes, liveliness and wall clock --

KEYS = RobotKeys()


@dataclass(frozen=True)
class Cmd:
    stamp_ns: int


class WallClock:
    """Wall seconds that pass only while someone waits."""

    def __init__(self) -> None:
        self.s = 0.0

    def __call__(self) -> float:
        return self.s


class FakeInbox(Generic[T]):
    """A `Fifo`: waiting on an empty one lets `timeout_s` of wall time pass."""

    def __init__(self, clock: WallClock) -> None:
        self.items: list[T] = []
        self.clock = clock
        self.on_wait: Callable[[], None] = lambda: None

    def pop(self, timeout_s: float = 0.0) -> T | None:
        if not self.items:
            self.wait(timeout_s)
        return self.items.pop(0) if self.items else None

    def drain(self) -> Iterator[T]:
        while self.items:
            yield self.items.pop(0)

    def wait(self, timeout_s: float) -> bool:
        if not self.items:
            self.clock.s += timeout_s
            self.on_wait()
        return bool(self.items)


class FakeAlive:
    """An `AliveWatch` whose tokens the test sets."""

    def __init__(self, *names: str) -> None:
        self.keys = {KEYS.alive(n) for n in names}
        self.version = 1
        self.waited: list[tuple[set[str], float]] = []

    def alive(self) -> set[str]:
        return set(self.keys)

    def only(self, *names: str) -> None:
        self.keys = {KEYS.alive(n) for n in names}
        self.version += 1

    def wait_for(
        self, keys: set[str], timeout_s: float, stop: threading.Event | None = None
    ) -> None:
        self.waited.append((keys, timeout_s))
        if stop is not None and stop.is_set():
            raise WaitTimeout("stopped")
        if not keys <= self.keys:
            raise WaitTimeout(f"not alive after {timeout_s:.3g} s: {sorted(keys - self.keys)}")


@dataclass
class Sim:
    gate: SimGate[Cmd]
    alive: FakeAlive
    acks: FakeInbox[Ack]
    commands: FakeInbox[Cmd]
    clock: WallClock
    stop: threading.Event


def sim(
    *alive: str,
    mode: Literal["lockstep", "realtime"] = "lockstep",
    on_back: Callable[[], None] | None = None,
) -> Sim:
    settings = TimeSettings(
        mode=mode,
        participants={
            "nav": Participant(role="periodic", period_s=0.05, latency_s=0.02),
            "wbc": Participant(role="command", period_s=0.002, latency_s=0.0),
            "eval": Participant(role="start"),
        },
        start_timeout_s=30.0,
        stall_timeout_s=1.0,
    )
    clock, stop = WallClock(), threading.Event()
    acks: FakeInbox[Ack] = FakeInbox(clock)
    commands: FakeInbox[Cmd] = FakeInbox(clock)
    watch = FakeAlive(*alive)
    gate = SimGate(
        settings,
        alive=watch,
        acks=acks,
        commands=commands,
        alive_key=KEYS.alive,
        stop=stop,
        log=logging.getLogger("test.sim"),
        now=clock,
        on_back=on_back,
    )
    gate.refresh(0)  # the sim's first tick
    return Sim(gate, watch, acks, commands, clock, stop)


@pytest.fixture
def s() -> Sim:
    """A lockstep sim at t = 0 with nav (periodic) and the WBC (command) alive."""
    return sim("nav", "wbc")


def test_the_start_gate_waits_once_for_every_participant_the_start_one_included() -> None:
    s = sim("nav", "wbc", "eval")
    s.gate.start()
    assert s.alive.waited == [({KEYS.alive(n) for n in ("nav", "wbc", "eval")}, 30.0)]
    s.alive.only("nav", "wbc")  # the start participant leaves: it is never waited for again
    s.gate.refresh(20 * MS)
    s.acks.items.append(Ack(service="nav", stamp_ns=0))
    s.gate.wait_acks(20 * MS)
    assert s.clock.s == 0.0 and s.gate.stalls == 0
    assert len(s.alive.waited) == 1


def test_the_start_gate_logs_the_missing_and_starts_anyway(
    s: Sim, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.ERROR):
        s.gate.start()
    assert "starting without every participant" in caplog.text and "eval" in caplog.text


def test_a_stop_at_the_start_gate_ends_the_wait_without_an_error(
    caplog: pytest.LogCaptureFixture,
) -> None:
    s = sim("nav", "wbc", "eval")
    s.stop.set()  # SIGTERM while the stack comes up: the gate hands its stop to the wait
    with caplog.at_level(logging.INFO):
        s.gate.start()
    assert "stopped at the start gate" in caplog.text
    assert "starting without every participant" not in caplog.text


def test_in_realtime_there_is_no_start_gate_and_the_newest_command_wins() -> None:
    s = sim(mode="realtime")
    s.gate.start()
    assert s.alive.waited == []
    s.commands.items += [Cmd(0), Cmd(1 * MS)]
    assert s.gate.command(1 * MS) == Cmd(1 * MS)
    assert s.gate.command(2 * MS) is None


def test_the_sim_publishes_once_the_acks_due_are_in(s: Sim) -> None:
    s.gate.wait_acks(19 * MS)  # nav's tick at 0 takes effect at 20 ms
    assert s.clock.s == 0.0
    s.acks.on_wait = lambda: s.acks.items.append(Ack(service="nav", stamp_ns=0))
    s.gate.wait_acks(20 * MS)
    assert s.clock.s == pytest.approx(0.05)  # one look, then the ack
    assert s.gate.acks.blocking(20 * MS) == [] and s.gate.stalls == 0


def test_a_participant_that_dies_is_not_waited_for(
    s: Sim, caplog: pytest.LogCaptureFixture
) -> None:
    s.acks.on_wait = lambda: s.alive.only("wbc")  # nav's liveliness goes while it is awaited
    with caplog.at_level(logging.WARNING):
        s.gate.wait_acks(20 * MS)
    assert "nav is gone at t=0.020 s" in caplog.text
    assert s.gate.stalls == 0 and s.clock.s < 1.0
    s.alive.only("nav")  # the commander dies: its answer is not waited for either
    s.gate.refresh(22 * MS)
    assert s.gate.wait_command(22 * MS) is None
    assert s.clock.s < 1.0


def cut_off(*steps: tuple[int, tuple[str, ...] | None]) -> tuple[Sim, list[float]]:
    """A sim (nav, the WBC and its own token alive) whose router goes at its first look
    for nav's ack: at each (look, names) of `steps` those tokens are alive (None: nav
    acks instead; each look is 0.05 s of wall time). Its `on_back` calls, in wall s."""
    sent_again: list[float] = []
    s = sim("sim", "nav", "wbc", on_back=lambda: sent_again.append(s.clock.s))
    script = {1: (), **dict(steps)}  # every token, its own too: the router went
    looks = 0

    def look() -> None:
        nonlocal looks
        looks += 1
        if looks not in script:
            return
        names = script[looks]
        if names is None:
            s.acks.items.append(Ack(service="nav", stamp_ns=0))
        else:
            s.alive.only(*names)

    s.acks.on_wait = look
    return s, sent_again


def test_the_sims_own_token_gone_is_its_link_the_world_holds_and_sends_again_once_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # 3 s later (past the 1 s stall timeout) every one is back, then nav acks
    s, sent_again = cut_off((60, ("sim", "nav", "wbc")), (61, None))
    with caplog.at_level(logging.WARNING):
        s.gate.wait_acks(20 * MS)
    assert s.clock.s == pytest.approx(3.05) and s.gate.stalls == 0
    assert "the sim's own link is down" in caplog.text and "the sim's link is back" in caplog.text
    assert "no longer waited for" not in caplog.text  # nobody let go
    assert sent_again == [pytest.approx(3.0)]
    assert s.gate.acks.blocking(20 * MS) == []


def test_back_on_its_link_the_sim_waits_for_the_others_to_reconnect_before_going_on() -> None:
    # its own link first: nav's retry comes later
    s, sent_again = cut_off((20, ("sim", "wbc")), (30, ("sim", "nav", "wbc")), (31, None))
    s.gate.wait_acks(20 * MS)
    assert sent_again == [pytest.approx(1.5)]  # once nav was back too, not before
    assert s.gate.stalls == 0 and "nav" in s.gate.alive_names


def test_a_participant_that_stalls_is_logged_and_stepped_without_until_it_acks(
    s: Sim, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO):
        s.gate.wait_acks(20 * MS)
        assert s.clock.s > 1.0 and s.gate.stalls == 1
        assert "nav stalled: no ack for t=0.020 s within 1.0 s" in caplog.text
        s.gate.wait_acks(70 * MS)  # not waited for while it is stalled
        assert s.clock.s < 1.1 and s.gate.stalls == 1
        s.acks.items.append(Ack(service="nav", stamp_ns=50 * MS))
        s.gate.drain_acks(100 * MS)  # it answers again: waited for from now on
    assert "nav answers again" in caplog.text
    assert s.gate.acks.blocking(120 * MS) == ["nav"]


def test_the_sim_steps_with_the_commander_s_answer_to_this_state(s: Sim) -> None:
    assert s.gate.state_due(2 * MS) and not s.gate.state_due(3 * MS)
    s.commands.items += [Cmd(0), Cmd(2 * MS)]
    assert s.gate.wait_command(3 * MS) is None  # no state at 3 ms: nothing is due
    assert s.gate.command(2 * MS) == Cmd(2 * MS)  # the answer to 0 ms is superseded
    assert s.commands.items == []


def test_a_commander_that_stalls_is_logged_and_stepped_without(
    s: Sim, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.ERROR):
        assert s.gate.wait_command(4 * MS) is None
    assert "wbc stalled at t=0.004 s" in caplog.text
    assert s.gate.stalls == 1 and s.clock.s > 1.0


def test_a_stopping_sim_waits_for_nobody(s: Sim) -> None:
    s.stop.set()
    s.gate.wait_acks(20 * MS)
    assert s.gate.wait_command(2 * MS) is None
    assert s.clock.s == 0.0 and s.gate.stalls == 0


def test_only_one_command_participant() -> None:
    settings = TimeSettings(
        participants={"a": Participant(role="command"), "b": Participant(role="command")}
    )
    with pytest.raises(ValueError, match="at most one command participant"):
        SimGate(
            settings,
            alive=FakeAlive(),
            acks=FakeInbox(WallClock()),
            commands=FakeInbox[Cmd](WallClock()),
            alive_key=KEYS.alive,
            stop=threading.Event(),
            log=logging.getLogger("test.sim"),
        )
