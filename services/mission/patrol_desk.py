"""The mapping jobs' desk: the patrol and the exploration asked for, driven, reported.

A mapping job (`goal_job.GoalJob`: the patrol's `PatrolRunner`, the exploration's
`ExploreRunner`) is asked for in one of two ways:

- `ask(request)`, the `dume/<r>/mission/patrol` queryable's handler (Zenoh's thread):
  `status` is answered at once with the status of the mission's last tick (whichever
  job it is); `start` (a patrol) and `stop` (whichever job runs) wait, at most
  `answer_s` wall seconds, until the loop has taken them at its next tick, and are
  answered with what it did (no tick in time: `timeout`, and the request is dropped);
- `start_request(b, request)`: a `mission/request` of task `explore` or `patrol`, handed
  over by the fetch's `Desk` (the loop's thread), which then reports its progress on
  `mission/status` from `report()` and cancels it through `cancel`.

`step(b, fetch)` runs on the loop's thread once a tick, after the fetch's `Desk`:

1. the queryable's requests taken, in arrival order: `start` is refused (state
   `rejected`, a typed reason) while a fetch runs (`fetch` names it) or a job does
   (`busy`), while a service the jobs depend on is not running (`unavailable`), or when
   no route can be planned (`plan_patrol`: `unavailable`, `no_route`); else the patrol
   starts and the dependencies are armed (one that raises is logged and refused
   `internal`). `stop` stops the running job;
2. a dependency that went away or restarted since the job started fails it
   `dependency_lost`; else the job steps once (one that raises is logged and the job
   failed `internal`); an exploration asked for by a request that ended `done` goes on
   with the semantic pass when `explore_semantic_pass` is set (a patrol facing the
   surfaces of the explored map, `plan_patrol(surfaces=True)`, the same request: stage
   `semantic_pass`), and a semantic pass that ended done with a second look at the
   artifacts in doubt when `patrol_second_look` is set and there are any
   (`plan_second_look`: stage `second_look`);
3. the queryable's requests are answered with the status after the step, which is also
   what `published(b)` gives the node to put on `mission/patrol/status` at every tick
   (the map waits for it in lockstep, and reads `arm_look` from it).

`busy_with()` says what a job blocks (a fetch's `Desk` refuses a request `busy` while one
runs). No Zenoh: the node serves `ask` and publishes.
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
from common.messages.mission import (
    MissionReason,
    MissionRequest,
    MissionState,
    PatrolRequest,
    PatrolStatus,
)
from services.mission.explore import ExploreRunner
from services.mission.goal_job import GoalJob
from services.mission.mission_log import MissionLogger
from services.mission.patrol import PatrolRefusal, PatrolRunner, plan_patrol, plan_second_look
from services.mission.ports import RobotPort

#: Wall seconds a start or stop waits for the loop to take it.
ANSWER_S = 20.0
#: A job's state as a request's (`mission/status`).
REQUEST_STATE: dict[str, MissionState] = {
    "running": "running",
    "done": "succeeded",
    "stopped": "cancelled",
    "failed": "failed",
}


@dataclass
class _Asked:
    """A start or stop waiting for the loop: taken at a tick, then answered."""

    request: PatrolRequest
    done: threading.Event = field(default_factory=threading.Event)
    taken: bool = False
    answer: PatrolStatus | None = None


@dataclass(frozen=True)
class JobReport:
    """A request's job as `mission/status` says it: its state, stage (`explore`,
    `patrol`, `semantic_pass`, `second_look`), progress in [0, 1], the typed reason and a
    sentence."""

    request_id: str
    state: MissionState
    stage: str
    progress: float
    reason: MissionReason = ""
    detail: str = ""


class PatrolDesk:
    """Mapping jobs in, the running one stepped, the status out (see the module
    docstring). `runner` is the patrol, `explorer` the exploration (None: this mission
    takes no explore requests)."""

    def __init__(
        self,
        runner: PatrolRunner,
        port: RobotPort,
        settings: MissionSettings,
        deps: Dependencies,
        log: MissionLogger,
        errors: logging.Logger,
        answer_s: float = ANSWER_S,
        explorer: ExploreRunner | None = None,
    ) -> None:
        self.runner, self.explorer = runner, explorer
        self.port, self.settings, self.deps = port, settings, deps
        self.log, self.errors, self.answer_s = log, errors, answer_s
        self._lock = threading.Lock()
        self._asked: list[_Asked] = []
        self._status = PatrolStatus(stamp_ns=0, state="idle")
        #: The job running or last run.
        self.job: GoalJob = runner
        #: The request the job serves ("" for one started on `mission/patrol`), its stage,
        #: and the exploration's word once its semantic pass runs.
        self.request_id = ""
        self.stage = ""
        self._explored = ""

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
        """What a fetch must wait for ("" when no job runs)."""
        if not self.job.running:
            return ""
        return "an exploration is running" if self.job.task == "explore" else (
            "a mapping patrol is running")  # fmt: skip

    def published(self, b: int) -> PatrolStatus:
        """The status to publish at tick b (the last step's, stamped b)."""
        with self._lock:
            return msgspec.structs.replace(self._status, stamp_ns=b)

    def start_request(self, request: MissionRequest) -> PatrolRefusal | None:
        """Start the job a request of task `explore` or `patrol` asks for; the refusal
        (`busy`, `unavailable`, `no_route`) or None (see the module docstring)."""
        refusal = self._refusal("")
        if refusal is None and request.task == "explore":
            refusal = self._start_explore()
        elif refusal is None:
            refusal = self._start(PatrolRequest(action="start"))
        if refusal is None:
            self.request_id, self.stage, self._explored = request.request_id, request.task, ""
        return refusal

    def cancel(self, request_id: str, reason: str) -> bool:
        """Stop the job of `request_id` at its next step; whether it is the running one."""
        if not self.request_id or request_id != self.request_id or not self.job.running:
            return False
        self.log.patrol(f"{self.job.task} of {request_id} cancelled: {reason}")
        self.job.stop(reason)
        return True

    def report(self) -> JobReport | None:
        """The request's job as of the last step (None: no request's job); once it has
        ended, reported once."""
        if not self.request_id:
            return None
        job = self.job
        state = REQUEST_STATE.get(job.state, "failed")
        if isinstance(job, ExploreRunner):
            progress, detail = job.progress(), job.summary()
        else:
            at = job.status(0)
            progress = at.waypoint / at.waypoints if at.waypoints else 0.0
            detail = f"viewpoint {at.waypoint} of {at.waypoints}"
        reason: MissionReason = job.reason
        if state != "running":
            detail = "; ".join(filter(None, (self._explored, job.detail)))
            reason = "cancelled" if state == "cancelled" else reason
            progress = 1.0 if state == "succeeded" else progress
        out = JobReport(self.request_id, state, self.stage, progress, reason, detail)
        if state != "running":
            self.request_id = ""
        return out

    def stalled(self, b: int) -> bool:
        """No tick for a while: a job whose dependency is gone (the sim above all) fails
        `dependency_lost`; whether one did."""
        lost = self.deps.lost() if self.job.running else None
        if lost is None:
            return False
        said = f"{lost}: the world stopped at t={b / NS_PER_S:.2f} s" if lost.startswith(
            "sim") else lost  # fmt: skip
        self.job.fail("dependency_lost", said)
        self.deps.disarm()
        self._publish_status(b)
        return True

    def step(self, b: int, fetch: str) -> PatrolStatus:
        """Tick b's requests, then the job's step; the status (see the module docstring).
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
        job = self.job
        was_running = job.running
        lost = self.deps.lost() if was_running else None
        try:
            if lost is not None:
                job.fail("dependency_lost", lost)
            else:
                job.step()
        except Exception:  # a bug: say it, end the job as safely as it can, keep serving
            self.errors.exception("the %s failed at t=%.2f s", job.task, b / NS_PER_S)
            with contextlib.suppress(Exception):
                job.fail("internal", f"the {job.task} raised: see the log")
            job.state, job.reason = "failed", "internal"
        if was_running and not job.running:
            self._next_stage(job)
            if not self.job.running:
                self.deps.disarm()
        status = self._publish_status(b)
        for asked in taken:
            if asked.answer is None:
                asked.answer = status
            asked.done.set()
        return status

    def _publish_status(self, b: int) -> PatrolStatus:
        status = self.job.status(b)
        with self._lock:
            self._status = status
        return status

    def _next_stage(self, job: GoalJob) -> None:
        """A request's exploration that ended done goes on with the semantic pass, and
        that with the second look."""
        if not self.request_id or job.state != "done":
            return
        if job is self.runner and self.stage == "semantic_pass":
            self._second_look()
            return
        if not (job is self.explorer and self.settings.explore_semantic_pass):
            return
        self._explored = f"explored: {job.detail}"
        refusal = self._start(PatrolRequest(action="start"), surfaces=True)
        if refusal is not None:
            self.log.patrol(f"semantic pass refused: {refusal.reason}: {refusal.detail}", True)
            job.state, job.reason = "failed", refusal.reason
            job.detail = f"the semantic pass could not start: {refusal.detail}"
            return
        self.stage = "semantic_pass"

    def _second_look(self) -> None:
        """The semantic pass ended done: look again at the artifacts in doubt, if any."""
        if not self.settings.patrol_second_look:
            return
        route = plan_second_look(self.port, self.settings, self.log.patrol)
        if route is None:
            return
        passed = self.runner.walker
        seen = f"semantic pass: {passed.viewpoint} viewpoints" if passed else ""
        self._explored = "; ".join(filter(None, (self._explored, seen)))
        self.runner.start(route)
        self.log.route(route)
        self.stage = "second_look"

    def _take(self, b: int, request: PatrolRequest, fetch: str) -> PatrolStatus | None:
        """A request taken at tick b: the refusal, or None (answered after the step)."""
        if request.action == "stop":
            if self.job.running:
                self.log.patrol(f"stop requested ({self.job.task})")
                self.job.stop()
            return None
        refusal = self._refusal(fetch) or self._start(request)
        if refusal is None:
            self.request_id = ""
            return None
        self.log.patrol(f"start refused: {refusal.reason}: {refusal.detail}", warn=True)
        return PatrolStatus(
            stamp_ns=b, state="rejected", reason=refusal.reason, detail=refusal.detail
        )

    def _refusal(self, fetch: str) -> PatrolRefusal | None:
        if self.job.running:
            what = "an exploration" if self.job.task == "explore" else "a patrol"
            return PatrolRefusal("busy", f"{what} is running; stop it first")
        if fetch:
            return PatrolRefusal("busy", f"{fetch}; a patrol waits for it to end")
        down = self.deps.missing()
        if down:
            return PatrolRefusal("unavailable", f"not running: {', '.join(down)}")
        return None

    def _start(self, request: PatrolRequest, surfaces: bool = False) -> PatrolRefusal | None:
        planned = plan_patrol(
            self.port, self.settings, request.spacing_m, self.log.patrol, surfaces
        )
        if isinstance(planned, PatrolRefusal):
            return planned
        self.runner.start(planned)
        self.job = self.runner
        self.deps.arm()
        self.log.route(planned)
        self.log.patrol(f"patrol started: {len(planned.viewpoints)} viewpoints")
        return None

    def _start_explore(self) -> PatrolRefusal | None:
        if self.explorer is None:
            return PatrolRefusal("unavailable", "this mission takes no explore requests")
        if self.port.robot_xy() is None:
            return PatrolRefusal("unavailable", "no odometry: is the sim running?")
        self.explorer.start()
        self.job = self.explorer
        self.deps.arm()
        self.log.patrol("exploration started")
        return None
