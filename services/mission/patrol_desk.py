"""The mapping patrol's desk: `mission/patrol` requests in, the patrol driven, its status out.

`ask(request)` is the `dume/<r>/mission/patrol` queryable's handler (Zenoh's thread):
`status` is answered at once with the status of the mission's last tick; `start` and
`stop` wait, at most `answer_s` wall seconds, until the loop has taken them at its next
tick, and are answered with what it did (no tick in time: `timeout`, and the request is
dropped).

`step(b, fetch)` runs on the loop's thread once a tick, after the fetch's `Desk`:

1. the requests taken, in arrival order: `start` is refused (state `rejected`, a typed
   reason) while a fetch runs (`fetch` names it) or a patrol does (`busy`), while a
   service the patrol depends on is not running (`unavailable`), or when no route can be
   planned (`plan_patrol`: `unavailable`, `no_route`); else the patrol starts and its
   dependencies are armed (one that raises is logged and refused `internal`). `stop`
   stops a running patrol;
2. a dependency that went away or restarted since the patrol started fails it
   `dependency_lost`; else the runner steps once (a runner that raises is logged and the
   patrol failed `internal`);
3. the requests are answered with the status after the step, which is also what
   `published(b)` gives the node to put on `mission/patrol/status` at every tick (the
   map waits for it in lockstep, and reads `arm_look` from it).

`busy_with()` says what the patrol blocks (a fetch's `Desk` refuses a request `busy`
while a patrol runs). No Zenoh: the node serves `ask` and publishes.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from dataclasses import dataclass, field

import msgspec

from common.bus import RequestError
from common.config import MissionSettings
from common.lifelines import Dependencies
from common.messages.base import NS_PER_S
from common.messages.mission import PatrolRequest, PatrolStatus
from services.mission.mission_log import MissionLogger
from services.mission.patrol import PatrolRefusal, PatrolRunner, plan_patrol
from services.mission.ports import RobotPort

#: Wall seconds a start or stop waits for the loop to take it.
ANSWER_S = 20.0


@dataclass
class _Asked:
    """A start or stop waiting for the loop: taken at a tick, then answered."""

    request: PatrolRequest
    done: threading.Event = field(default_factory=threading.Event)
    taken: bool = False
    answer: PatrolStatus | None = None


class PatrolDesk:
    """Patrol requests in, the runner stepped, the status out (see the module docstring)."""

    def __init__(
        self,
        runner: PatrolRunner,
        port: RobotPort,
        settings: MissionSettings,
        deps: Dependencies,
        log: MissionLogger,
        errors: logging.Logger,
        answer_s: float = ANSWER_S,
    ) -> None:
        self.runner, self.port, self.settings, self.deps = runner, port, settings, deps
        self.log, self.errors, self.answer_s = log, errors, answer_s
        self._lock = threading.Lock()
        self._asked: list[_Asked] = []
        self._status = PatrolStatus(stamp_ns=0, state="idle")

    # -- Zenoh's thread -------------------------------------------------------------------

    def ask(self, request: PatrolRequest | None, _selector: str) -> PatrolStatus:
        """The queryable's handler (see the module docstring)."""
        assert request is not None  # served with a request type: Server decoded it
        if request.action == "status":
            with self._lock:
                return self._status
        asked = _Asked(request)
        with self._lock:
            self._asked.append(asked)
        for _ in range(2):  # once taken, the tick that took it answers
            if asked.done.wait(self.answer_s):
                break
            with self._lock:
                if not asked.taken:
                    self._asked.remove(asked)
                    break
        if asked.answer is None:
            raise RequestError(
                "timeout", f"the mission did not take the {request.action} in {self.answer_s:g} s"
            )
        return asked.answer

    @property
    def pending(self) -> int:
        """Starts and stops waiting for the loop."""
        with self._lock:
            return len(self._asked)

    # -- the loop's thread ----------------------------------------------------------------

    def busy_with(self) -> str:
        """What a fetch must wait for ("" when no patrol runs)."""
        return "a mapping patrol is running" if self.runner.running else ""

    def published(self, b: int) -> PatrolStatus:
        """The status to publish at tick b (the last step's, stamped b)."""
        with self._lock:
            return msgspec.structs.replace(self._status, stamp_ns=b)

    def step(self, b: int, fetch: str) -> PatrolStatus:
        """Tick b's requests, then the patrol's step; the status (see the module docstring).
        `fetch`: the running fetch in a few words ("" when none runs)."""
        with self._lock:
            taken, self._asked = self._asked, []
            for asked in taken:
                asked.taken = True
        for asked in taken:
            try:
                asked.answer = self._take(b, asked.request, fetch)
            except Exception:  # a bug: say it, refuse, keep serving
                self.errors.exception("the patrol's %s failed", asked.request.action)
                asked.answer = PatrolStatus(
                    stamp_ns=b, state="rejected", reason="internal", detail="see the log"
                )
        was_running = self.runner.running
        lost = self.deps.lost() if was_running else None
        try:
            if lost is not None:
                self.runner.fail("dependency_lost", lost)
            else:
                self.runner.step()
        except Exception:  # a bug: say it, end the patrol as safely as it can, keep serving
            self.errors.exception("the patrol failed at t=%.2f s", b / NS_PER_S)
            with contextlib.suppress(Exception):
                self.runner.fail("internal", "the patrol raised: see the log")
            self.runner.state, self.runner.reason = "failed", "internal"
        if was_running and not self.runner.running:
            self.deps.disarm()
        status = self.runner.status(b)
        with self._lock:
            self._status = status
        for asked in taken:
            if asked.answer is None:
                asked.answer = status
            asked.done.set()
        return status

    def _take(self, b: int, request: PatrolRequest, fetch: str) -> PatrolStatus | None:
        """A request taken at tick b: the refusal, or None (answered after the step)."""
        if request.action == "stop":
            if self.runner.running:
                self.log.patrol("stop requested")
                self.runner.stop()
            return None
        refusal = self._refusal(fetch) or self._start(request)
        if refusal is None:
            return None
        self.log.patrol(f"start refused: {refusal.reason}: {refusal.detail}", warn=True)
        return PatrolStatus(
            stamp_ns=b, state="rejected", reason=refusal.reason, detail=refusal.detail
        )

    def _refusal(self, fetch: str) -> PatrolRefusal | None:
        if self.runner.running:
            return PatrolRefusal("busy", "a patrol is running; stop it first")
        if fetch:
            return PatrolRefusal("busy", f"{fetch}; a patrol waits for it to end")
        down = self.deps.missing()
        if down:
            return PatrolRefusal("unavailable", f"not running: {', '.join(down)}")
        return None

    def _start(self, request: PatrolRequest) -> PatrolRefusal | None:
        planned = plan_patrol(self.port, self.settings, request.spacing_m, self.log.patrol)
        if isinstance(planned, PatrolRefusal):
            return planned
        self.runner.start(planned)
        self.deps.arm()
        self.log.route(planned)
        self.log.patrol(f"patrol started: {len(planned.viewpoints)} viewpoints")
        return None
