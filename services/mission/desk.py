"""One mission tick's work once its inputs are in: requests, cancels, the tree, the status.

`Desk.step(b)` (the loop's thread, sim time b in ns), in this order:

1. the first step (since the mission started) sets the status `idle` with no request and
   the sim time it started at, so a client whose request was in progress hears it lost;
   before it, a request the last mission of this run held when it stopped (`journal`)
   is failed `dependency_lost` by its id, with the stage it was in;
2. requests drained from the inbox: parsed, refused at once (a `rejected` status
   published stamped b) when malformed, when a mission or a mapping job runs (`busy`;
   `busy_with` names the job), when a dependency is not running (`unavailable`) or when
   the map does not know the object or the person (`check_request`, a fetch's only);
   else the tree starts (a fetch, or a `put_back` of what the gripper still holds), the
   dependencies are armed and `accepted` is published. A request of task
   `explore` or `patrol` goes to the mapping jobs' desk (`jobs.start_request`: refused
   `busy`, `unavailable`, `no_route`), `accepted` with its stage;
3. cancels drained from the inbox: one of the running request stops the tree
   (`MissionTree.cancel`) or its mapping job (`jobs.cancel`); others are logged and
   ignored;
4. a dependency that went away or restarted since the running request started
   (`Dependencies.lost`) fails it `dependency_lost`; else the tree ticks once (a
   behaviour that raises is logged, the robot halted, the mission failed `internal`).
   A dependency whose token went is first held for (`Dependencies.noticed`: from 0.3 s
   after it went until `HOLD_S`): the status says so at once ("holding: sim not heard
   (<the leaf running>)"), and the request goes on if it comes back as the same process;
5. the outcome, or the running stage and progress, becomes the status
   (`StatusBoard.update`): `step` returns whether it changed.

`job_status(b)`, once the jobs' desk stepped, puts a request's mapping job on the status
(`jobs.report`: running with its stage and progress, then its outcome). `flush(b,
changed)` then publishes the status stamped b when it changed or the periodic repeat is
due (the node calls it after the robot's own outputs for b are out).

No Zenoh and no lock: everything here runs on the loop's thread; the inboxes are the
only things other threads touch. `send` publishes a status; `errors` is the service's
logger (the mission's tree and requests are told through `MissionLogger`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from common.lifelines import Dependencies
from common.messages.base import NS_PER_S
from common.messages.mission import MissionReason, MissionRequest, MissionState, MissionStatus
from services.mission.behaviours.abort import halt
from services.mission.inbox import Inbox
from services.mission.journal import Journal
from services.mission.mission_log import MissionLogger
from services.mission.ports import RobotPort
from services.mission.requests import (
    Rejection,
    StatusBoard,
    check_request,
    parse_cancel,
    parse_request,
)
from services.mission.tree import MissionTree, Outcome


class JobRefusal(Protocol):
    @property
    def reason(self) -> MissionReason: ...
    @property
    def detail(self) -> str: ...


class JobReport(Protocol):
    @property
    def request_id(self) -> str: ...
    @property
    def state(self) -> MissionState: ...
    @property
    def stage(self) -> str: ...
    @property
    def progress(self) -> float: ...
    @property
    def reason(self) -> MissionReason: ...
    @property
    def detail(self) -> str: ...


class Jobs(Protocol):
    """The mapping jobs' desk as the fetch's desk sees it (`patrol_desk.PatrolDesk`)."""

    def busy_with(self) -> str: ...
    def start_request(self, request: MissionRequest) -> JobRefusal | None: ...
    def cancel(self, request_id: str, reason: str) -> bool: ...
    def report(self) -> JobReport | None: ...
    def stalled(self, b: int) -> bool: ...


class Desk:
    """Requests in, the tree driven, the status out (see the module docstring)."""

    def __init__(
        self,
        tree: MissionTree,
        robot: RobotPort,
        deps: Dependencies,
        board: StatusBoard,
        requests: Inbox,
        cancels: Inbox,
        log: MissionLogger,
        send: Callable[[MissionStatus], None],
        errors: logging.Logger,
        busy_with: Callable[[], str] | None = None,
        jobs: Jobs | None = None,
        journal: Journal | None = None,
    ) -> None:
        self.tree, self.robot, self.deps, self.board = tree, robot, deps, board
        self.requests, self.cancels = requests, cancels
        self.log, self.send, self.errors = log, send, errors
        #: The mapping jobs' desk (None: this mission takes fetches only).
        self.jobs = jobs
        #: What else runs that a request must wait for (a mapping job), "" when nothing.
        self.busy_with: Callable[[], str] = busy_with or (jobs.busy_with if jobs else lambda: "")
        #: Whether the first step ran (the `idle` status of a (re)start is set).
        self.started = False
        #: The request held, on disk: a restarted mission says what it lost.
        self.journal = journal or Journal(None)
        #: Requests sent ahead of their `at_ns`, held until the tick reaches it.
        self.held: list[MissionRequest] = []
        #: The dependencies the running request holds for (noticed gone, not yet lost).
        self.waiting: list[str] = []

    # -- the status -----------------------------------------------------------------------

    def _publish(self, status: MissionStatus) -> None:
        self.send(status)
        self.log.status(status)
        self.journal.note(status)

    def stalled(self, b: int) -> bool:
        """The clock stopped after tick b (no tick for a while): when a dependency of
        the running request is gone (the sim above all: no clock comes from a dead
        world), the request fails `dependency_lost` stamped b, and the robot is halted;
        whether the status changed. Nobody waits for the dead, even without ticks."""
        request = self.tree.request
        if self.jobs is not None and self.jobs.stalled(b):
            return self.job_status(b)
        lost = self.deps.lost() if request is not None else None
        if request is None:
            return False
        if lost is None:
            return self._wait_for(b, self.tree.where()[1])
        said = f"{lost}: the world stopped at t={b / NS_PER_S:.2f} s" if lost.startswith(
            "sim") else lost  # fmt: skip
        self.errors.error("t=%.2f s: %s: the mission fails", b / NS_PER_S, said)
        outcome = self.tree.fail("dependency_lost", said)
        self.deps.disarm()
        self.waiting = []
        if outcome is None:
            return False
        return self.board.update(
            b, request.request_id, outcome.state, self.board.status.behaviour,
            self.board.status.progress, outcome.reason, outcome.detail,
        )  # fmt: skip

    def _wait_for(self, b: int, detail: str) -> bool:
        """The running request holds for a dependency noticed gone (not yet lost): its
        status says whom it waits for; whether that is news (said at once: the policy's
        0.5 s to notice a loss)."""
        request, waiting = self.tree.request, self.deps.noticed()
        news = bool(waiting) and waiting != self.waiting
        if news:
            self.errors.warning(
                "t=%.2f s: %s not heard: holding for it up to %.1f s",
                b / NS_PER_S, " and ".join(waiting), self.deps.hold_s,
            )  # fmt: skip
        elif self.waiting and not waiting:
            self.errors.warning("t=%.2f s: %s back: the request goes on", b / NS_PER_S,
                                " and ".join(self.waiting))  # fmt: skip
        self.waiting = waiting
        if waiting and request is not None:  # every status while it holds says so
            st = self.board.status
            self.board.update(
                b, request.request_id, st.state, st.behaviour, st.progress,
                detail=f"holding: {' and '.join(waiting)} not heard ({detail})",
            )  # fmt: skip
        return news

    def notice(self, b: int) -> None:
        """Between ticks (a tick waiting on a dependency's inputs): a dependency of the
        running request newly noticed gone is said now, stamped b."""
        if self.tree.request is None or not (self.waiting or self.deps.noticed()):
            return  # nothing to say (the common case: called every slice of a wait)
        if self._wait_for(b, self.tree.where()[1]):
            self.flush(b, True)

    def flush(self, b: int, changed: bool) -> None:
        """Publish the status stamped b when it changed or the periodic repeat is due."""
        if changed or self.board.due(b):
            self._publish(self.board.sent(b))

    # -- requests and cancels -------------------------------------------------------------

    def _reject(self, b: int, rejection: Rejection) -> None:
        self.log.request(
            f"request {rejection.request_id or '(no id)'} rejected: "
            f"{rejection.reason}: {rejection.detail}",
            warn=True,
        )
        self._publish(
            MissionStatus(
                stamp_ns=b,
                request_id=rejection.request_id,
                state="rejected",
                reason=rejection.reason,
                detail=rejection.detail,
            )
        )

    def _incoming(self, b: int) -> list[MissionRequest | Rejection]:
        """What arrived, in order, with the requests held for a later tick left out and
        those held before whose tick came put first (`MissionRequest.at_ns`)."""
        due = [r for r in self.held if r.at_ns is None or r.at_ns <= b]
        self.held = [r for r in self.held if r.at_ns is not None and r.at_ns > b]
        out: list[MissionRequest | Rejection] = list(due)
        for payload in self.requests.drain():
            parsed = parse_request(payload)
            if isinstance(parsed, MissionRequest) and parsed.at_ns is not None and parsed.at_ns > b:
                self.log.request(
                    f"request {parsed.request_id}: held until t={parsed.at_ns / 1e9:.2f} s"
                )
                self.held.append(parsed)
                continue
            out.append(parsed)
        return out

    def _requests(self, b: int) -> None:
        for parsed in self._incoming(b):
            if isinstance(parsed, Rejection):
                self._reject(b, parsed)
                continue
            if parsed.task not in ("fetch", "put_back"):
                self._job(b, parsed)
                continue
            said = f"{parsed.object} to {parsed.person}" if parsed.task == "fetch" else "put back"
            self.log.request(f"request {parsed.request_id}: {said}")
            if self.tree.busy:
                running = self.tree.request.request_id if self.tree.request else ""
                self._reject(
                    b, Rejection(parsed.request_id, "busy", f"mission {running} is running")
                )
                continue
            other = self.busy_with()
            if other:
                self._reject(b, Rejection(parsed.request_id, "busy", other))
                continue
            down = self.deps.missing()
            refused = (
                Rejection(parsed.request_id, "unavailable", f"not running: {', '.join(down)}")
                if down
                else check_request(parsed, self.robot)
                if parsed.task == "fetch"
                else None
            )
            if refused is not None:
                self._reject(b, refused)
                continue
            self._start(b, parsed)

    def _job(self, b: int, request: MissionRequest) -> None:
        """A request of task `explore` or `patrol`: to the mapping jobs' desk."""
        rid = request.request_id
        self.log.request(f"request {rid}: {request.task}")
        refused: Rejection | None = None
        if self.jobs is None:
            refused = Rejection(rid, "unavailable", f"this mission takes no {request.task}")
        elif self.tree.busy:
            running = self.tree.request.request_id if self.tree.request else ""
            refused = Rejection(rid, "busy", f"mission {running} is running")
        else:
            job_refused = self.jobs.start_request(request)
            if job_refused is not None:
                refused = Rejection(rid, job_refused.reason, job_refused.detail)
        if refused is not None:
            self._reject(b, refused)
            return
        self.board.update(b, rid, "accepted", request.task, detail=f"{request.task} started")
        self._publish(self.board.sent(b))

    def job_status(self, b: int) -> bool:
        """A request's mapping job onto the status, after the jobs' desk stepped; whether
        the status changed."""
        report = self.jobs.report() if self.jobs is not None else None
        if report is None:
            return False
        r = report
        return self.board.update(b, r.request_id, r.state, r.stage, r.progress, r.reason, r.detail)

    def _start(self, b: int, request: MissionRequest) -> None:
        self.tree.start(request)
        self.deps.arm()
        said = "checked against the map" if request.task == "fetch" else "put back what it holds"
        self.board.update(b, request.request_id, "accepted", detail=said)
        self._publish(self.board.sent(b))

    def _cancels(self) -> Outcome | None:
        outcome = None
        for payload in self.cancels.drain():
            cancel = parse_cancel(payload)
            current = self.tree.request
            if cancel is None:
                self.log.request(f"cancel ignored: not a MissionCancel: {payload[:200]!r}", True)
            elif self.jobs is not None and self.jobs.cancel(
                cancel.request_id, cancel.reason or "cancelled by the user"
            ):
                self.log.request(f"cancel of {cancel.request_id}: {cancel.reason}")
            elif current is None or cancel.request_id != current.request_id:
                running = current.request_id if current else "none"
                self.log.request(
                    f"cancel of {cancel.request_id} ignored: the running mission is {running}",
                    True,
                )
            else:
                self.log.request(f"cancel of {cancel.request_id}: {cancel.reason}")
                outcome = self.tree.cancel(cancel.reason or "cancelled by the user")
        return outcome

    # -- the step -------------------------------------------------------------------------

    def step(self, b: int) -> bool:
        """Tick b's requests, cancels and tree; whether the status changed."""
        self.log.at(b)
        if not self.started:  # (re)started: no request is in progress, and clients hear it
            self.started = True
            if (interrupted := self.journal.take(b)) is not None:
                self.errors.error("request %s: %s", interrupted.request_id, interrupted.detail)
                self._publish(interrupted)
            self.board.update(b, "", "idle", detail=f"mission started at t={b / NS_PER_S:.2f} s")
        self._requests(b)
        request = self.tree.request
        outcome = self._cancels()
        lost = self.deps.lost() if outcome is None and request is not None else None
        if lost is not None:
            self.errors.error("t=%.2f s: %s: the mission fails", b / NS_PER_S, lost)
            outcome = self.tree.fail("dependency_lost", lost)
        if outcome is None:
            try:
                outcome = self.tree.tick()
            except Exception:
                self.errors.exception("the tree failed at t=%.2f s", b / NS_PER_S)
                if self.tree.cancel("internal error") is None:
                    halt(self.robot, "internal error")
                outcome = Outcome("failed", "internal", "a behaviour raised: see the log")
        self.log.tree(self.tree.statuses(), self.tree.text)
        if outcome is not None and request is not None:
            self.deps.disarm()
            self.waiting = []
            done = 1.0 if outcome.state == "succeeded" else self.board.status.progress
            return self.board.update(
                b,
                request.request_id,
                outcome.state,
                self.board.status.behaviour,
                done,
                outcome.reason,
                outcome.detail,
            )
        if self.tree.request is not None:
            stage, leaf, progress = self.tree.where()
            changed = self.board.update(
                b, self.tree.request.request_id, "running", stage, progress, detail=leaf
            )
            return self._wait_for(b, leaf) or changed
        return False
