"""The semantic map's feed: fetched as of a tick on a thread of its own, adopted on sim time.

Times are ns of sim time. The loop calls `tick(b)` at each of its ticks: at every tick b
that is a multiple of `refresh_ns` with no fetch in flight, it asks for the map as of b;
the fetch thread (`run`, started by `start`: a query may take seconds, which the
lockstep loop must not) fetches the grid and people as of b from the `Source`, in that
order, and hands them back (a failure is logged once per new sentence and handed back as
its sentence). `MAP_ADOPT_S` after the fetch's tick, `tick` returns what came (grid,
people, the tick they are as of) for the loop to adopt: in lockstep it waits for the
fetch up to `timeout_s` wall seconds (so every run adopts it at the same tick), and a
fetch that failed or never came is dropped; in realtime a fetch still out is adopted at
the first tick after it is in.

Locks: `cond` (the node's one condition, shared with `intake.GoalIntake`) guards the
fetch in flight; the fetch thread notifies it when a result is in; `tick` runs on the
loop's thread only, `run` on the fetch thread only.
"""

from __future__ import annotations

import logging
import threading

from common.messages.base import NS_PER_S
from services.navigation.costmap import Person
from services.navigation.grid import Grid
from services.navigation.sources import Source, SourceError

#: Sim seconds from a map fetch's tick to the tick that adopts it.
MAP_ADOPT_S = 0.25


class MapFeed:
    """The fetch in flight and its thread; see the module docstring."""

    def __init__(
        self,
        source: Source,
        cond: threading.Condition,
        log: logging.Logger,
        *,
        lockstep: bool,
        refresh_ns: int,
        timeout_s: float,
    ) -> None:
        self.source, self.log = source, log
        self.lockstep, self.refresh_ns, self.timeout_s = lockstep, refresh_ns, timeout_s
        self._ticked = cond
        #: The map fetch in flight: (its tick, the result once in: grid and people, or the
        #: error's sentence).
        self._fetch: tuple[int, tuple[Grid, list[Person]] | str | None] | None = None
        self._fetch_due = threading.Event()

    def start(self, stop: threading.Event) -> None:
        """Run the fetch thread until `stop` is set."""
        threading.Thread(target=self.run, args=(stop,), name="map", daemon=True).start()

    def run(self, stop: threading.Event) -> None:
        """The semantic map's grid and people as of the tick the loop asks for (the fetch
        thread)."""
        said = ""
        while not stop.is_set():
            if not self._fetch_due.wait(0.2):
                continue
            self._fetch_due.clear()
            with self._ticked:
                if self._fetch is None:
                    continue
                b = self._fetch[0]
            try:
                got: tuple[Grid, list[Person]] | str = (
                    self.source.grid(at_ns=b),
                    self.source.people(at_ns=b),
                )
                said = ""
            except SourceError as exc:
                got = str(exc)
                if got != said:
                    self.log.warning("map unavailable: %s", exc)
                    said = got
            with self._ticked:
                if self._fetch is not None and self._fetch[0] == b:
                    self._fetch = (b, got)
                    self._ticked.notify_all()

    def tick(self, b: int) -> tuple[Grid, list[Person], int] | None:
        """Ask for the map at every `refresh_ns`; the fetch to adopt at b, if any (grid,
        people and the tick they are as of)."""
        with self._ticked:
            fetch = self._fetch
            if fetch is None or b < fetch[0] + round(MAP_ADOPT_S * NS_PER_S):
                fetch = None  # none in flight, or not due yet
            elif fetch[1] is None and self.lockstep:  # every run adopts it at this tick
                self._ticked.wait_for(
                    lambda: self._fetch is None or self._fetch[1] is not None, self.timeout_s
                )
                fetch = self._fetch
                if fetch is not None and fetch[1] is None:
                    self.log.warning("map fetch of t=%.2f s never came: dropped", fetch[0] / 1e9)
            if fetch is not None and (fetch[1] is not None or self.lockstep):
                self._fetch = None  # adopted (or failed, or given up)
            else:
                fetch = None  # realtime: adopted at the first tick after it is in
            if self._fetch is None and b % self.refresh_ns == 0:
                self._fetch = (b, None)
                self._fetch_due.set()
        got = None if fetch is None else fetch[1]
        return (*got, fetch[0]) if isinstance(got, tuple) and fetch is not None else None
