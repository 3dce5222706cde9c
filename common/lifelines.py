"""Nobody waits for the dead: which of the services a job depends on went away.

A job (a mission request, a demo's or an eval's watch of one) depends on some services.
`Lifelines` is what Zenoh's liveliness said about them: who is alive now and how often
each one's token went away (a service that supervisord restarted within one tick of the
watcher still counts: its token went, then came back). `Dependencies.lost()` names the
first one that went away since the job started, as a sentence for the typed reason
`dependency_lost` ("mission restarted", "navigation is gone").

`OwnLink` tells a lost token from the watcher's own Zenoh link lapsing (a client the
router cut off sees every token go and come back), for a client that follows a job
from outside the stack (`dume eval`'s watch, `dume request --wait`).

Pure bookkeeping: `common.bus.AliveWatch` feeds a `Lifelines` from Zenoh's liveliness
subscriber; a unit test feeds it by hand.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable


class Lifelines:
    """Who is alive (liveliness keys) and how often each one's token went away."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._losses: dict[str, int] = {}

    def up(self, key: str) -> None:
        with self._lock:
            self._alive.add(key)

    def down(self, key: str) -> None:
        with self._lock:
            if key in self._alive:
                self._alive.discard(key)
                self._losses[key] = self._losses.get(key, 0) + 1

    def snapshot(self) -> tuple[frozenset[str], dict[str, int]]:
        """(who is alive, how often each key went away) now."""
        with self._lock:
            return frozenset(self._alive), dict(self._losses)


#: This many dependencies (or more), every one of them gone at once: it is the router
#: (or the host) that went, not each service.
ROUTER_LOST_AT = 3


class Dependencies:
    """The services one job depends on, watched from when it started (`arm`).

    `key_of(name)` is the service's liveliness key. `lost()` is None while every one of
    them alive at `arm` is still the same process; else "<name> restarted" (it went away
    and is back) or "<name> is gone"; or, every one of `ROUTER_LOST_AT` or more gone
    together, "the router is gone: every service went at once (…)": the link to them
    all, not each process (a killed router said "sim is gone: the world stopped").
    """

    def __init__(
        self, lifelines: Lifelines, names: Iterable[str], key_of: Callable[[str], str]
    ) -> None:
        self._lifelines = lifelines
        self._keys = {name: key_of(name) for name in names}
        self.names = list(self._keys)
        self._armed: dict[str, int] = {}

    def missing(self) -> list[str]:
        """The dependencies not alive now (a job should not start without them)."""
        alive, _ = self._lifelines.snapshot()
        return [n for n, k in self._keys.items() if k not in alive]

    def arm(self) -> None:
        """The job starts now: from here on, a dependency that goes away is lost."""
        alive, losses = self._lifelines.snapshot()
        self._armed = {n: losses.get(k, 0) for n, k in self._keys.items() if k in alive}

    def disarm(self) -> None:
        self._armed = {}

    def lost(self) -> str | None:
        alive, losses = self._lifelines.snapshot()
        keys = self._keys
        gone = [n for n, before in self._armed.items()
                if losses.get(keys[n], 0) > before and keys[n] not in alive]  # fmt: skip
        if len(gone) >= ROUTER_LOST_AT and len(gone) == len(self._armed):
            return f"the router is gone: every service went at once ({', '.join(gone)})"
        for name, before in self._armed.items():
            key = self._keys[name]
            if losses.get(key, 0) > before:
                return f"{name} restarted" if key in alive else f"{name} is gone"
        return None


#: Wall seconds a lost token is doubted (`OwnLink`): every watched token back and the
#: clock on within it, the watcher's own link lapsed. Well inside the fault trial's
#: `HUNG_S` (a hung mission's loss ends a watch about 1 + 5 s after the SIGSTOP).
LAPSE_GRACE_S = 5.0


class OwnLink:
    """Whose loss a lost dependency is: the service's, or this watcher's own link's.

    A client whose session the router closed (it read nothing for 0.5 s, or said nothing
    for its 1 s lease) reconnects by itself, its subscriptions and the tokens it sees
    come back, and it counts every token as gone once (`Lifelines`): as if every
    service had restarted. `verdict` tells them apart: "fine" (nothing lost), "doubt"
    (lost, not yet known whose), "lapse" (every watched token is back and the clock ran
    past where it stood at the loss: the world went on; the caller re-arms), "lost"
    (`grace_s` of wall time went by otherwise: a service's loss). A sim restarted
    under us starts its clock again from 0, and a mission restarted under us reports
    our request itself, so neither passes for a lapse.
    """

    def __init__(self, grace_s: float = LAPSE_GRACE_S) -> None:
        self.grace_s = grace_s
        self._since: float | None = None
        self._at_ns = 0
        #: The sim time (ns) of each lapse the watch went on through.
        self.lapses: list[int] = []

    def verdict(self, lost: bool, now_s: float, clock_ns: int, all_back: bool) -> str:
        """`lost`: a watched token went since the watch was armed; `now_s`: wall time
        (monotonic); `clock_ns`: the newest clock; `all_back`: every watched token is
        alive now."""
        if not lost:
            self._since = None
            return "fine"
        if self._since is None:
            self._since, self._at_ns = now_s, clock_ns
        if all_back and clock_ns > self._at_ns:
            self.lapses.append(self._at_ns)
            self._since = None
            return "lapse"
        return "lost" if now_s - self._since >= self.grace_s else "doubt"
