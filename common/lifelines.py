"""Nobody waits for the dead: which of the services a job depends on went away.

A job (a mission request, a demo's or an eval's watch of one) depends on some services.
`Lifelines` is what Zenoh's liveliness said about them: who is alive now, how often
each one's token went away and when (a service that supervisord restarted within one
tick of the watcher still counts: its token went, then came back), and which run of it
is alive: every service process declares a second token with its run, a random id of
that process (`RobotKeys.alive_run`). `Dependencies.lost()` names the first one that
went away since the job started, as a sentence for the typed reason `dependency_lost`
("mission restarted", "navigation is gone").

A token can go while its process lives: the router closes the link of a client that
read nothing for 0.5 s (a GIL held by one long call; `deploy/zenoh/router.json5`), and
the client reconnects by itself once it reads again, within 10 ms, its tokens with
it. A hall exploration failed `dependency_lost: semantic_map restarted` at t = 540 s on
such a lapse, with the map's process running throughout. So a dependency whose token
went is first doubted: back as the same run, it lapsed (the job goes on, the lapse is
counted); back as another run, it restarted; not back within `LOST_GRACE_S` of wall
time from when its token went, it is noticed (`noticed`: the policy's 0.5 s to notice a
loss); not back within `hold_s` (the mission's `HOLD_S`), it is gone. A watcher that
acts at once on a loss holds `hold_s` = the grace; the mission holds longer: a shift's
request failed `dependency_lost: sim is gone` on a lapse of the sim's link that the
0.3 s grace ended 0.16 s before the sim came back as the same process (a killed sim or
WBC: the world pauses or the sim's watchdog holds the robot meanwhile). Every dependency
gone at once is the link to them all: the router (restarted by supervisord in about
1.2 s) or the watcher's own session (cut off, or starved on a loaded host: a hall
exploration's mission, with a second stack on its two cores, lost every token for more
than 0.4 s). That is doubted `LAPSE_GRACE_S`: every one back as the same run, the world
only paused (a lockstep sim waits for its participants) and the job goes on.

`OwnLink` tells a lost token from the watcher's own Zenoh link lapsing (a client the
router cut off sees every token go and come back), for a client that follows a job
from outside the stack (`dume eval`'s watch, `dume request --wait`).

Pure bookkeeping: `common.bus.AliveWatch` feeds a `Lifelines` from Zenoh's liveliness
subscriber; a unit test feeds it by hand.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable

#: Wall seconds a dependency's lost token is doubted before it is noticed, from when
#: its token went. A lapse lasts what was left of the stall that caused it after the
#: router's cut, its token back 4-7 ms after the client reads again (`dume bench lapse`:
#: a subscriber stalled 2 s under 100 MB/s was gone 0.15-0.59 s, 3 s 1.57-1.60 s; 1.5 s
#: was cut off in one run of three rounds and not in another). It was 0.4 s, counted
#: from the watcher's next look: a kill was said 0.42-0.51 s after (the policy's 0.5 s to
#: notice).
LOST_GRACE_S = 0.3
#: Wall seconds from when its token went that a job that can wait (the mission's
#: request: the world pauses or the robot holds while a dependency is away) holds a
#: noticed loss for the same run to come back before it counts as gone: a lapse of a 2 s
#: stall was gone 0.15-0.59 s, of a 3 s one 1.6 s (`dume bench lapse`); a killed WBC or
#: sim must end the request within the policy's 1 s.
HOLD_S = 0.8
#: Wall seconds a watcher looks at a lost token at least, however long ago it went: one
#: starved of the CPU for seconds (a shift's mission, a second stack on its two cores)
#: first sees the loss with the token's return still queued behind it.
LOOK_AGAIN_S = 0.1
#: Wall seconds a lost token is doubted when every one went at once (`Dependencies`),
#: and by `OwnLink`: every watched token back (and the clock on) within it, the link
#: lapsed. Well inside the fault trial's `HUNG_S` (a hung mission's loss ends a watch
#: about 1 + 5 s after the SIGSTOP).
LAPSE_GRACE_S = 5.0


class Lifelines:
    """Who is alive (liveliness keys) and how often each one's token went away."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._lock = threading.Lock()
        self._clock = clock
        self._alive: set[str] = set()
        self._losses: dict[str, int] = {}
        self._lost_at: dict[str, float] = {}
        self._runs: dict[str, set[str]] = {}

    def up(self, key: str) -> None:
        with self._lock:
            self._alive.add(key)

    def run_up(self, key: str, run: str) -> None:
        """The run `run` of the service whose liveliness key is `key` is alive."""
        with self._lock:
            self._runs.setdefault(key, set()).add(run)

    def run_down(self, key: str, run: str) -> None:
        with self._lock:
            self._runs.get(key, set()).discard(run)

    def runs(self, key: str) -> frozenset[str]:
        """The runs of `key`'s service alive now (one, but for a restart's overlap)."""
        with self._lock:
            return frozenset(self._runs.get(key, ()))

    def down(self, key: str) -> None:
        with self._lock:
            if key in self._alive:
                self._alive.discard(key)
                self._losses[key] = self._losses.get(key, 0) + 1
                self._lost_at[key] = self._clock()

    def lost_at(self, key: str) -> float | None:
        """When (this one's clock) `key`'s token last went away; None if it never did."""
        with self._lock:
            return self._lost_at.get(key)

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
    them alive at `arm` is still the same process; else "<name> restarted" (another
    run of it is alive) or "<name> is gone" (none, `hold_s` after its token went:
    `noticed` from `grace_s`); or,
    every one of `ROUTER_LOST_AT` or more gone together and not back in
    `LAPSE_GRACE_S`, "the router is gone: every service went at once (…)": the link to
    them all, not each process (a killed router said "sim is gone: the world stopped").
    A token back as the run armed is a lapse (`take_lapses`), not a loss. A run heard
    only after `arm` (a watch just made) is taken as the armed one while the token has
    not gone; a service whose run is not known (a token without its run token) counts
    as restarted when its token comes back.
    """

    def __init__(
        self,
        lifelines: Lifelines,
        names: Iterable[str],
        key_of: Callable[[str], str],
        grace_s: float = LOST_GRACE_S,
        clock: Callable[[], float] = time.monotonic,
        link_grace_s: float = LAPSE_GRACE_S,
        hold_s: float | None = None,
    ) -> None:
        self._lifelines = lifelines
        self._keys = {name: key_of(name) for name in names}
        self.names = list(self._keys)
        self.grace_s, self.link_grace_s, self._clock = grace_s, link_grace_s, clock
        #: How long a noticed loss waits for the same run before it is gone (>= grace).
        self.hold_s = grace_s if hold_s is None else max(hold_s, grace_s)
        #: Per dependency alive at `arm`: its token's losses then, and its run.
        self._armed: dict[str, tuple[int, str | None]] = {}
        #: Since when (wall) a dependency's token has been gone, unresolved, and when this
        #: watcher first looked at it gone.
        self._doubt: dict[str, tuple[float, float]] = {}
        #: The doubted ones that went with every other (the link: `link_grace_s`).
        self._link_doubt: set[str] = set()
        #: The dependencies whose token went and came back as the same run, in order,
        #: not yet taken (`take_lapses`).
        self._lapses: list[str] = []
        #: The doubted ones past the grace, not yet gone (`noticed`), as of `lost`.
        self._noticed: list[str] = []

    def missing(self) -> list[str]:
        """The dependencies not alive now (a job should not start without them)."""
        alive, _ = self._lifelines.snapshot()
        return [n for n, k in self._keys.items() if k not in alive]

    def arm(self) -> None:
        """The job starts now: from here on, a dependency that goes away is lost."""
        alive, losses = self._lifelines.snapshot()
        self._armed = {
            n: (losses.get(k, 0), _one(self._lifelines.runs(k)))
            for n, k in self._keys.items()
            if k in alive
        }
        self._doubt, self._link_doubt, self._noticed = {}, set(), []

    def disarm(self) -> None:
        self._armed = {}
        self._doubt, self._link_doubt, self._noticed = {}, set(), []

    def take_lapses(self) -> list[str]:
        """The lapses seen since the last call (a watcher logs them)."""
        out, self._lapses = self._lapses, []
        return out

    def doubted(self) -> list[str]:
        """The dependencies whose token is gone, not yet known lapsed or lost."""
        return list(self._doubt)

    def noticed(self) -> list[str]:
        """The doubted ones gone past the grace and held for (`hold_s`), as of the
        last `lost`: a job says it waits for them."""
        return list(self._noticed)

    def lost(self) -> str | None:
        alive, losses = self._lifelines.snapshot()
        now = self._clock()
        gone: list[str] = []
        self._noticed = []
        restarted: str | None = None
        link = len(self._armed) >= ROUTER_LOST_AT and all(
            losses.get(self._keys[n], 0) > before and self._keys[n] not in alive
            for n, (before, _) in self._armed.items()
        )
        if link:  # they went together: each one is doubted as long, back or not
            self._link_doubt.update(self._armed)
        for name, (before, run) in list(self._armed.items()):
            link_doubt = name in self._link_doubt
            grace = self.link_grace_s if link_doubt else self.grace_s
            hold = self.link_grace_s if link_doubt else self.hold_s
            key = self._keys[name]
            if losses.get(key, 0) <= before:
                if run is None and (run := _one(self._lifelines.runs(key))) is not None:
                    self._armed[name] = (before, run)  # its run heard after `arm`
                continue
            runs = self._lifelines.runs(key)
            if run is not None and runs - {run}:
                restarted = restarted or name
            elif run is not None and run in runs and key in alive:  # the same process
                self._armed[name] = (losses.get(key, 0), run)
                self._doubt.pop(name, None)
                self._link_doubt.discard(name)
                self._lapses.append(name)
            elif run is None and key in alive:
                restarted = restarted or name
            else:  # doubted from when its token went, not from when a tick saw it
                went = self._lifelines.lost_at(key)
                since, looked = self._doubt.setdefault(
                    name, (now if went is None else min(went, now), now)
                )
                looked_enough = now - looked >= min(grace, LOOK_AGAIN_S)
                if now - since >= hold and looked_enough:
                    gone.append(name)
                elif now - since >= grace and looked_enough:
                    self._noticed.append(name)
        if len(gone) >= ROUTER_LOST_AT and len(gone) == len(self._armed):
            return f"the router is gone: every service went at once ({', '.join(gone)})"
        for name in self._armed:
            if name == restarted:
                return f"{name} restarted"
            if name in gone:
                return f"{name} is gone"
        return None


def _one(runs: frozenset[str]) -> str | None:
    """The run of a service when exactly one is alive; None when unknown."""
    return next(iter(runs)) if len(runs) == 1 else None


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
