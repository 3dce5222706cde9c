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

Zenoh keeps the order of one key's samples, not across keys: a subscriber's callbacks
for different keys run concurrently, so a clock can overtake the odom published before
it, and a producer's ack can overtake its output. Lockstep therefore never relies on
order across keys: a participant waits for each input stamped with the tick it needs
(`Latest.wait_stamp`), and a consumer of a periodic producer's output waits, with
`UpstreamGate`, for that output stamped with the producer's tick that takes effect now
(producers publish every period, so the sample always comes).

The whole protocol is in this module: `AckGate` is the bookkeeping (unit-tested without
Zenoh), used by the sim's `SimGate` and by `UpstreamGate`; `SimGate` is the sim's side (the
start gate at t = 0, "may the sim publish at t?", "the command for t", stalls and
liveliness); `PeriodicTicker` is a periodic participant's side, `UpstreamGate` a
consumer's.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from common.bus import AliveWatch, Bus, WaitTimeout
from common.config import Config, Participant, TimeSettings
from common.keys import WORLD_CLOCK, RobotKeys, service_of_alive_key
from common.messages.base import NS_PER_S
from common.messages.sim import Ack, Clock

log = logging.getLogger(__name__)

#: The sim publishes the clock at least this often (ns), for services that only watch time.
CLOCK_EVERY_NS = 10_000_000


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


T_co = TypeVar("T_co", covariant=True)


class Stamped(Protocol):
    """A message stamped with sim time, ns (a `JointCommand` with the state's it answers)."""

    @property
    def stamp_ns(self) -> int: ...


C = TypeVar("C", bound=Stamped)


class Inbox(Protocol[T_co]):
    """Samples of one key in arrival order, filled by another thread: a `Fifo`."""

    def pop(self, timeout_s: float = 0.0) -> T_co | None: ...

    def drain(self) -> Iterator[T_co]: ...

    def wait(self, timeout_s: float) -> bool: ...


class Liveliness(Protocol):
    """Who is alive, kept current by another thread: an `AliveWatch`."""

    @property
    def version(self) -> int: ...

    def alive(self) -> set[str]: ...

    def wait_for(
        self, keys: set[str], timeout_s: float, stop: threading.Event | None = None
    ) -> None: ...


#: Wall seconds the sim blocks on one look for an ack or a command before it looks again
#: at liveliness, its stall deadline and whether it is stopping.
POLL_S = 0.05
#: Wall seconds the sim, its own link back, waits for the services alive before it
#: lost it to reconnect too (each retries the router on its own backoff, up to 0.5 s).
LINK_BACK_S = 5.0
#: Wall seconds the last clock and state are sent again after the link came back, and
#: how often, while nobody answers.
RESEND_FOR_S = 3.0
RESEND_EVERY_S = 0.25


class SimGate(Generic[C]):
    """The sim's half of lockstep: whom it waits for, when it may publish, what it steps with.

    Per tick t (sim ns), from the sim's loop thread only (the inboxes and the liveliness
    watch are filled by Zenoh's threads): `refresh(t)` takes liveliness joins and leaves;
    in lockstep `wait_acks(t)` returns once the sim may publish at t (every live periodic
    participant acked its ticks whose outputs take effect by t; in realtime `drain_acks(t)`
    only books the acks); after publishing, `command(t)` is what to step with. Before the
    first tick `start()` is the start gate. Waits are bounded in wall seconds: a
    participant whose liveliness goes is no longer waited for, one that stalls past
    `time.stall_timeout_s` is logged (`log`, the sim's logger), counted in `stalls` and
    stepped without until it answers again.

    `alive_key(name)` is a participant's liveliness key; a key's last segment is its
    service's name. `now` is the wall clock (s) the deadlines read.

    The sim's own token (`own`) gone from its own watch is its link to the router gone
    (the router killed, or this session cut off), not every participant dying: the
    world holds (`cut_off`: no participant is let go, the waits for acks and commands
    go on past `stall_timeout_s`) until the link is back and every service alive before
    it is back too (or `LINK_BACK_S` went by: the late ones are let go), and then
    `on_back` sends again what the participants wait for (the last clock and state),
    every `RESEND_EVERY_S` until answered or `RESEND_FOR_S` went by (sent at once, they
    reached nobody: a publisher hears of its subscribers again a while after). A
    router killed while navigating let the world run 9 s of sim time without the WBC's
    commands (every participant "gone"), and the robot fell; held, the world waits for
    the router's restart.
    """

    def __init__(
        self,
        settings: TimeSettings,
        *,
        alive: Liveliness,
        acks: Inbox[Ack],
        commands: Inbox[C],
        alive_key: Callable[[str], str],
        stop: threading.Event,
        log: logging.Logger,
        now: Callable[[], float] = time.perf_counter,
        own: str = "sim",
        on_back: Callable[[], None] | None = None,
    ) -> None:
        self.settings = settings
        self.own = own
        self._on_back = on_back
        #: The sim's own token is gone from its watch: its link is (class docstring).
        self.cut_off = False
        self._back_since: float | None = None
        #: (next due, until) wall seconds while the last clock and state are sent again.
        self._resend: tuple[float, float] | None = None
        self.lockstep = settings.mode == "lockstep"
        self.tick_ns = round(NS_PER_S / settings.tick_hz)
        self.acks = AckGate(settings.participants, self.tick_ns)
        commanders = [n for n, p in settings.participants.items() if p.role == "command"]
        if len(commanders) > 1:
            raise ValueError(f"at most one command participant, got {commanders}")
        #: The command participant (the sim waits for its answer to every state), or None.
        self.commander = commanders[0] if commanders else None
        #: The state goes out (and a command is due) at each multiple of this, ns.
        self.command_period_ns = (
            round(settings.participants[self.commander].period_s * NS_PER_S)
            if self.commander
            else self.tick_ns
        )
        #: Services alive now, by name (every service, not only participants).
        self.alive_names: set[str] = set()
        #: Stalls logged: a periodic participant's once until it acks again, the
        #: commander's once per state it left unanswered.
        self.stalls = 0
        #: Wall seconds waited per participant, booked to the one that answered last.
        self.waited_s: dict[str, float] = {}
        self._alive = alive
        self._alive_version = -1
        self._ack_inbox = acks
        self._commands = commands
        self._alive_key = alive_key
        self._stop = stop
        self._log = log
        self._now = now

    def start(self) -> None:
        """The start gate, before the first tick (lockstep with participants only): wait up
        to `start_timeout_s` until every configured participant (every role: the `start`
        ones are waited for here and never again) is alive; else log and start anyway.
        A stop ends the wait (a sim told to stop as its stack came up waited out the
        120 s, SIGTERM and all)."""
        if not (self.lockstep and self.settings.participants):
            return
        wanted = {self._alive_key(n) for n in self.settings.participants}
        self._log.info("lockstep: waiting for %s", sorted(self.settings.participants))
        try:
            self._alive.wait_for(wanted, self.settings.start_timeout_s, self._stop)
        except Exception as exc:
            if self._stop.is_set():
                self._log.info("lockstep: stopped at the start gate (%s)", exc)
            else:
                self._log.error("starting without every participant: %s", exc)

    def state_due(self, t_ns: int) -> bool:
        """Publish the state at t? When the commander answers it (every tick without one)."""
        return t_ns % self.command_period_ns == 0

    def clock_due(self, t_ns: int) -> bool:
        """Publish the clock at t? At every participant boundary and every 10 ms."""
        return self.acks.clock_due(t_ns, CLOCK_EVERY_NS)

    def refresh(self, t_ns: int) -> None:
        """Take the liveliness changes (if any) as of sim time t: joins and leaves, logged."""
        if self._alive.version == self._alive_version and not self.cut_off:
            return
        self._alive_version = self._alive.version
        names = {service_of_alive_key(k) for k in self._alive.alive()}
        if self.own in self.alive_names and self.own not in names and not self.cut_off:
            self.cut_off, self._back_since = True, None
            self._log.warning(
                "t=%.3f s: the sim's own link is down (its token gone from its own watch): "
                "the world holds until it is back", t_ns / NS_PER_S,
            )  # fmt: skip
        if self.cut_off:
            if self.own not in names:
                self._back_since = None
                return  # who is there is not known while cut off: nobody is let go
            if self._back_since is None:
                self._back_since = self._now()
            late = self.alive_names - names
            if late and self._now() - self._back_since < LINK_BACK_S:
                return  # the others reconnect in turn: wait for them before going on
            self.cut_off = False
            self._log.warning(
                "t=%.3f s: the sim's link is back%s", t_ns / NS_PER_S,
                f"; not back in {LINK_BACK_S:g} s: {sorted(late)}" if late else "",
            )  # fmt: skip
            # what went out while cut off was lost: sent again until answered (the
            # publishers hear of their subscribers again some time after the link)
            now = self._now()
            self._resend = (now, now + RESEND_FOR_S)
            self._send_again()
        for name in sorted(names - self.alive_names):
            self._log.info("%s is alive at t=%.3f s", name, t_ns / NS_PER_S)
            self.acks.join(name, t_ns)
        for name in sorted(self.alive_names - names):
            self._log.warning("%s is gone at t=%.3f s: no longer waited for", name, t_ns / NS_PER_S)
            self.acks.leave(name)
        self.alive_names = names

    def _send_again(self) -> None:
        """`on_back` every `RESEND_EVERY_S` while `RESEND_FOR_S` after the link came back
        has not passed and the sim is still waiting at the tick it held on (a later clock
        or state would make the one sent again stale: the waits clear it as they end)."""
        if self._resend is None or self._on_back is None:
            return
        due, until = self._resend
        now = self._now()
        if now > until:
            self._resend = None
        elif now >= due:
            self._on_back()
            self._resend = (now + RESEND_EVERY_S, until)

    def drain_acks(self, t_ns: int) -> None:
        """Book the acks that arrived; a stalled participant that acks again rejoins at t."""
        for ack in self._ack_inbox.drain():
            stalled = ack.service in self.acks.schedules and ack.service not in self.acks.alive
            if stalled and ack.service in self.alive_names:  # a stalled participant is back
                self._log.info("%s answers again", ack.service)
                self.acks.join(ack.service, t_ns)
            self.acks.ack(ack.service, ack.stamp_ns)

    def wait_acks(self, t_ns: int) -> None:
        """Return once the sim may publish at t (lockstep): no live periodic participant
        owes an ack due by t, or the sim is stopping, or `stall_timeout_s` (wall) passed:
        then each participant still owing is logged, counted and left until it acks."""
        start = self._now()
        deadline = start + self.settings.stall_timeout_s
        last: list[str] = []
        while True:
            self.drain_acks(t_ns)
            blocking = self.acks.blocking(t_ns)
            if not blocking or self._stop.is_set():
                self._book(last, start)
                self._resend = None  # what goes out next is newer than the last sent
                return
            self._send_again()
            last = blocking
            if self.cut_off:  # nobody is heard; the world holds
                deadline = self._now() + self.settings.stall_timeout_s
            if self._now() > deadline:
                for name in blocking:
                    self._log.error(
                        "%s stalled: no ack for t=%.3f s within %.1f s; stepping without it",
                        name,
                        t_ns / NS_PER_S,
                        self.settings.stall_timeout_s,
                    )
                    self.acks.leave(name)
                    self.stalls += 1
                self._resend = None
                return
            self._ack_inbox.wait(timeout_s=POLL_S)  # wakes on the next ack
            self.refresh(t_ns)

    def command(self, t_ns: int) -> C | None:
        """What to step with after publishing at t: in lockstep the commander's answer to
        the state at t (`wait_command`), in realtime the newest command that arrived."""
        if self.lockstep:
            return self.wait_command(t_ns)
        latest = None
        for latest in self._commands.drain():  # noqa: B007 - newest wins
            pass
        return latest

    def wait_command(self, t_ns: int) -> C | None:
        """The command answering the state at t (lockstep), or None if none is due/alive.

        Answers to older states are dropped (superseded). None, too, when the commander
        is gone, the sim is stopping, or `stall_timeout_s` (wall) passed (logged, counted).
        """
        if self.commander is None or t_ns % self.command_period_ns:
            return None
        start = self._now()
        deadline = start + self.settings.stall_timeout_s
        while self.commander in self.alive_names and not self._stop.is_set():
            cmd = self._commands.pop(timeout_s=POLL_S)
            if cmd is not None:
                if cmd.stamp_ns == t_ns:
                    self._book([self.commander], start)
                    self._resend = None  # answered: the link carries again
                    return cmd
                continue  # an answer to an older state: superseded
            self._send_again()
            if self.cut_off:  # nobody is heard; the world holds
                deadline = self._now() + self.settings.stall_timeout_s
            if self._now() > deadline:
                self._log.error("%s stalled at t=%.3f s", self.commander, t_ns / NS_PER_S)
                self.stalls += 1
                self._resend = None
                return None
            self.refresh(t_ns)
        return None

    def _book(self, names: list[str], start: float) -> None:
        """Book the wall time since `start` to `names` (split evenly), if any."""
        if not names:
            return
        share = (self._now() - start) / len(names)
        for name in names:
            self.waited_s[name] = self.waited_s.get(name, 0.0) + share


def _at_or_after(stamp_ns: int) -> Callable[[Clock], bool]:
    return lambda c: c.stamp_ns >= stamp_ns


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
        self._ack = bus.publisher(keys.ack(name), Ack, "control", again=True)
        self._name = name
        self._stop = stop

    def ticks(
        self, poll_s: float = 0.1, on_idle: Callable[[], None] | None = None
    ) -> Iterator[int]:
        """The ticks; `on_idle()` is called every `poll_s` wall seconds the clock does not
        reach the next one (a participant can notice that the world stopped)."""
        next_ns: int | None = None
        while not self._stop.is_set():
            clock = self.clock.get()
            target = 0 if next_ns is None else next_ns
            if clock is None or clock.stamp_ns < target:
                try:
                    clock = self.clock.wait(_at_or_after(target), poll_s)
                except WaitTimeout:
                    if on_idle is not None:
                        on_idle()
                    continue
            stamp = (clock.stamp_ns // self.period_ns) * self.period_ns
            next_ns = stamp + self.period_ns
            yield stamp

    def ack(self, stamp_ns: int) -> None:
        self._ack.put(Ack(service=self._name, stamp_ns=stamp_ns))

    def run(self, tick: Callable[[int], None]) -> None:
        """`tick(b)` at each tick, acked whatever it did (an exception goes on up)."""
        for b in self.ticks():
            try:
                tick(b)
            finally:
                self.ack(b)


#: Wall seconds a participant waits, at its first tick, to hear of the participants the
#: sim already heard of (`hear_all`).
HEAR_S = 10.0


def hear_all(alive: AliveWatch, keys: set[str], timeout_s: float = HEAR_S) -> bool:
    """At a participant's first tick: wait until it has heard that `keys` are alive.

    The sim starts only once every configured participant is alive, but this process's
    news of their liveliness can trail the clock (another key, another path), and a
    participant that thinks a producer is not running does not wait for its outputs:
    its first ticks would then depend on the machine's load. False (logged) when some
    stay unheard of: then they are not running.
    """
    try:
        alive.wait_for(keys, min(timeout_s, HEAR_S))
    except WaitTimeout as exc:
        log.warning("starting without hearing of every participant: %s", exc)
        return False
    return True


class Output(Protocol):
    """A producer's output as a consumer holds it: a `Latest`, or the consumer's own store
    (the gate must see the very samples the consumer will read, not a second copy)."""

    def get(self) -> Any: ...

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> Any: ...


class UpstreamGate:
    """A consumer's wait for the outputs of the periodic producers it applies in lockstep.

    `watch(producer, subscription)` names a producer's output (one key, published every
    period, stamped with the producer's tick). Before acting at sim time t, `wait(t)`
    blocks until each live producer's newest output is stamped at or after its tick that
    takes effect by t; then `subscription.at(t − latency_ns(producer))` is that output.
    A producer that is not alive is not waited for; one that came alive at t owes nothing
    before t. In realtime mode it never waits.
    """

    def __init__(self, bus: Bus, keys: RobotKeys, config: Config) -> None:
        self._participants = config.time.participants
        self._tick_ns = round(NS_PER_S / config.time.tick_hz)
        self.gate = AckGate({}, self._tick_ns)
        self.lockstep = config.time.mode == "lockstep"
        self._outputs: dict[str, Output] = {}
        self._alive = bus.watch_alive(keys.alive_all)
        self._alive_key = keys.alive
        self._version = -1
        self._heard = False

    def watch(self, producer: str, output: Output) -> None:
        p = self._participants.get(producer)
        if p is None or p.role != "periodic":
            return  # not a periodic participant: its outputs apply on arrival
        self.gate.schedules[producer] = Schedule.of(p)
        self._outputs[producer] = output
        self._version = -1

    def latency_ns(self, producer: str) -> int:
        s = self.gate.schedules.get(producer)
        return s.latency_ns if s else 0

    def _refresh(self, t_ns: int) -> None:
        if self._alive.version != self._version:
            self._version = self._alive.version
            alive_keys = self._alive.alive()
            alive = {p for p in self.gate.schedules if self._alive_key(p) in alive_keys}
            for p in alive - self.gate.alive:
                self.gate.join(p, t_ns)
            for p in self.gate.alive - alive:
                self.gate.leave(p)
        for p, output in self._outputs.items():
            newest = output.get()
            if newest is not None:
                self.gate.ack(p, newest.stamp_ns)

    def wait(
        self, t_ns: int, timeout_s: float, producers: Collection[str] | None = None
    ) -> list[str]:
        """Wait until the outputs due by t are in (of `producers` only, when given); the
        producers still missing (if any)."""
        if not self.lockstep or not self._outputs:
            return []
        if not self._heard:
            self._heard = True
            hear_all(self._alive, {self._alive_key(p) for p in self._outputs})
        deadline = time.perf_counter() + timeout_s
        while True:
            self._refresh(t_ns)
            missing = self.gate.blocking(t_ns)
            if producers is not None:
                missing = [p for p in missing if p in producers]
            if not missing or time.perf_counter() > deadline:
                return missing
            need = self.gate.schedules[missing[0]].required_ack(t_ns)
            with contextlib.suppress(WaitTimeout):
                self._outputs[missing[0]].wait_stamp(need, 0.05)
