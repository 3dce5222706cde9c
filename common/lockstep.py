"""Lockstep time: the sim steps only when every live participant has caught up.

The sim owns time on a 1 kHz tick. Each tick it publishes the clock and the state at t,
waits for the command participant's answer to that state (the whole-body controller),
steps, and before it publishes anything at the next tick t' it waits until every live
periodic participant has acknowledged each of its ticks b whose outputs take effect by
then (b + latency ≤ t'). A periodic participant (perception, navigation, mission) runs
on sim time: at each multiple b of its period it reads its inputs as of b (the newest
sample stamped ≤ b), publishes outputs stamped b, then acks b. Its consumers apply an
output from b at b + latency. The pipeline's delays are therefore modelled, not left to
the scheduler: the same seed gives the same run whatever the machine's load.

`AckGate` is the sim's side as plain bookkeeping (unit-tested without Zenoh);
`PeriodicTicker` is a participant's side.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from common.bus import Bus, WaitTimeout
from common.config import Participant
from common.keys import WORLD_CLOCK, RobotKeys
from common.messages.sim import Ack, Clock

NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Schedule:
    """A participant's period and latency in ns."""

    period_ns: int
    latency_ns: int

    @classmethod
    def of(cls, p: Participant) -> Schedule:
        return cls(round(p.period_s * NS_PER_S), round(p.latency_s * NS_PER_S))

    def last_boundary(self, t_ns: int) -> int:
        """The newest of its ticks at or before t (−1 before the first)."""
        return (t_ns // self.period_ns) * self.period_ns if t_ns >= 0 else -1

    def required_ack(self, t_ns: int) -> int:
        """The newest tick whose outputs take effect at or before t (−1: none yet)."""
        due = t_ns - self.latency_ns
        return self.last_boundary(due) if due >= 0 else -1


class AckGate:
    """The sim's bookkeeping of periodic participants' acks.

    `blocking(t)` names the live participants whose ack the sim still needs before it may
    publish state at t. A participant that comes alive mid-run owes nothing before the
    moment it joined; one that dies is no longer waited for.
    """

    def __init__(self, participants: Mapping[str, Participant], tick_ns: int) -> None:
        self.schedules = {
            name: Schedule.of(p) for name, p in participants.items() if p.role == "periodic"
        }
        for name, s in self.schedules.items():
            if s.latency_ns < tick_ns:
                raise ValueError(
                    f"participant {name}: latency {s.latency_ns} ns is shorter than one tick "
                    f"({tick_ns} ns); the sim could never publish the clock it needs"
                )
        self.acked: dict[str, int] = {}
        self.alive: set[str] = set()

    def join(self, name: str, t_ns: int) -> None:
        """`name` came alive at sim time t: it owes acks only for its ticks after t."""
        if name in self.schedules:
            self.alive.add(name)
            prior = self.schedules[name].last_boundary(t_ns - 1) if t_ns > 0 else -1
            self.acked[name] = max(self.acked.get(name, -1), prior)

    def leave(self, name: str) -> None:
        self.alive.discard(name)

    def ack(self, name: str, stamp_ns: int) -> None:
        if name in self.schedules:
            self.acked[name] = max(self.acked.get(name, -1), stamp_ns)

    def blocking(self, t_ns: int) -> list[str]:
        return [
            name
            for name in sorted(self.alive)
            if self.acked.get(name, -1) < self.schedules[name].required_ack(t_ns)
        ]

    def clock_due(self, t_ns: int, every_ns: int) -> bool:
        """Publish the clock at t? At every participant boundary and every `every_ns`."""
        if t_ns % every_ns == 0:
            return True
        return any(t_ns % s.period_ns == 0 for s in self.schedules.values())


class PeriodicTicker:
    """A periodic participant's ticks on sim time.

    `ticks()` yields each multiple of the period as the sim's clock reaches it (skipping to
    the newest one after a late start); process inputs as of that stamp, publish, then
    `ack(stamp)`. In realtime mode acks are harmless and the same code runs.
    """

    def __init__(
        self, bus: Bus, keys: RobotKeys, name: str, period_s: float, stop: threading.Event
    ) -> None:
        self.period_ns = round(period_s * NS_PER_S)
        self.clock = bus.latest(WORLD_CLOCK, Clock)
        self._ack = bus.publisher(keys.ack(name), Ack, "control")
        self._name = name
        self._stop = stop

    def ticks(self, poll_s: float = 0.1) -> Iterator[int]:
        next_ns: int | None = None
        while not self._stop.is_set():
            clock = self.clock.get()
            target = 0 if next_ns is None else next_ns
            if clock is None or clock.stamp_ns < target:
                try:
                    clock = self.clock.wait(lambda c, t=target: c.stamp_ns >= t, poll_s)
                except WaitTimeout:
                    continue
            stamp = (clock.stamp_ns // self.period_ns) * self.period_ns
            next_ns = stamp + self.period_ns
            yield stamp

    def ack(self, stamp_ns: int) -> None:
        self._ack.put(Ack(service=self._name, stamp_ns=stamp_ns))
