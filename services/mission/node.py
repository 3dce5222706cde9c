"""The mission service: a 20 Hz lockstep participant that ticks the bring-me tree.

Requests and cancels arrive as raw JSON (so a malformed one can still be answered with
its `request_id`) and wait in a queue for the loop; a request can also come as a query
(`mission/submit`), answered once it is in that queue, so a client knows it was heard.
Each tick b (multiples of `time.participants.mission.period_s`):

1. inputs as of b: the odom stamped b (50 Hz, waited for), the `wbc/status` stamped
   before b (waited for while the controller is alive), and the outputs of navigation
   and perception that take effect by b (`UpstreamGate`);
2. requests: parsed, refused at once when malformed, when a mission runs (`busy`), when
   a service it depends on is not running (`unavailable`) or when the map does not know
   the object or the person; else the tree starts; cancels of the running request stop
   the tree (`MissionTree.cancel`);
3. a dependency (the WBC, navigation, perception, the map: those of `time.participants`)
   that went away or restarted since the request started fails it `dependency_lost`
   (nobody waits for the dead); else the tree ticks once; its outcome, stage and
   progress become the status;
4. published stamped b: cmd_vel from source `mission` (zero unless a behaviour drives),
   a wbc mode when asked for, the status on change and every `status_every_s`; then the
   ack. A bug in a behaviour is logged with its traceback, the robot halted and the
   mission failed `internal`; the loop goes on.

A mission that (re)starts says so: its first status is `idle` with no request and the
sim time it started at, so a client whose request was in progress knows it was lost and
can send it again.
"""

from __future__ import annotations

import threading
from collections import deque

import zenoh

from common.bus import WaitTimeout
from common.lifelines import Dependencies
from common.lockstep import PeriodicTicker, UpstreamGate, hear_all
from common.messages import encode
from common.messages.base import NS_PER_S
from common.messages.mission import MissionReceipt, MissionRequest, MissionStatus
from common.service import Service
from services.mission.algorithms import default_algorithms
from services.mission.behaviours.abort import halt
from services.mission.behaviours.base import Context
from services.mission.mission_log import MissionLogger
from services.mission.requests import (
    Rejection,
    StatusBoard,
    check_request,
    parse_cancel,
    parse_request,
)
from services.mission.robot import WRIST, BusRobot
from services.mission.tree import MissionTree, Outcome

NAME = "mission"
#: The services a running mission depends on (those that are lockstep participants).
DEPENDENCIES = ("wbc", "navigation", "perception", "semantic_map")


class RawInbox:
    """Payloads of one key, kept raw for the loop (Zenoh's thread only appends)."""

    def __init__(self, session: zenoh.Session, key: str, maxlen: int = 256) -> None:
        self._q: deque[bytes] = deque(maxlen=maxlen)
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self.push(sample.payload.to_bytes())

    def push(self, payload: bytes) -> None:
        with self._lock:
            self._q.append(payload)

    def drain(self) -> list[bytes]:
        with self._lock:
            out = list(self._q)
            self._q.clear()
        return out


class MissionNode:
    """The loop and what it keeps between ticks; see the module docstring."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        m = cfg.mission
        self.period_s = cfg.time.period_of(NAME, 0.05)
        latency = cfg.time.latencies_ns()
        bus, keys = svc.bus, svc.keys
        self.robot = BusRobot(bus, keys, m.query_timeout_s, latency, m.sighting_gate_m)
        self.gate = UpstreamGate(bus, keys, cfg)
        self.gate.watch("navigation", self.robot.nav)
        self.gate.watch("perception", self.robot.detections)
        self.alive = bus.watch_alive(keys.alive_all)
        self.wbc_alive_key = keys.alive("wbc")
        needed = [n for n in DEPENDENCIES if n in cfg.time.participants]
        self.deps = Dependencies(self.alive.lifelines, needed, keys.alive)
        self.started = False
        self.status_period_ns = round(NS_PER_S / cfg.wbc.status_hz)
        self.requests = RawInbox(bus.session, keys.mission_request)
        bus.serve(keys.mission_submit, MissionRequest, self._on_submit)
        self.cancels = RawInbox(bus.session, keys.mission_cancel)
        self.status_pub = bus.publisher(keys.mission_status, MissionStatus, "data")
        self.log = MissionLogger(svc.rec, svc.log)
        ctx = Context(self.robot, m, default_algorithms(m), self.log.decision)
        self.tree = MissionTree(ctx)
        self.board = StatusBoard(round(m.status_every_s * NS_PER_S))
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_s, svc.stop)

    def run(self) -> None:
        self.svc.ready()
        for b in self.ticker.ticks():
            try:
                self.tick(b)
            except Exception:  # a bug: say it, stop the robot, keep serving
                self.svc.log.exception("mission tick at t=%.2f s failed", b / NS_PER_S)
            finally:
                self.ticker.ack(b)

    # -- inputs ---------------------------------------------------------------------------

    def _wait_inputs(self, b: int) -> None:
        timeout = self.svc.config.mission.input_timeout_s
        if not self.started and self.gate.lockstep:  # its first tick: know who runs
            hear_all(self.alive, {self.svc.keys.alive(n) for n in self.deps.names}, timeout)
        try:
            self.robot.odom.wait_stamp(b, timeout)
        except WaitTimeout:
            self.svc.log.warning("no odom for t=%.2f s", b / NS_PER_S)
        if b > 0 and self.wbc_alive_key in self.alive.alive():
            need = ((b - 1) // self.status_period_ns) * self.status_period_ns
            try:
                self.robot.wbc.wait_stamp(need, timeout)
            except WaitTimeout:
                self.svc.log.warning("no wbc/status for t=%.2f s", need / NS_PER_S)
        missing = self.gate.wait(b, timeout)
        if missing:
            self.svc.log.warning("t=%.2f s: no output of %s in time", b / NS_PER_S, missing)
        self.robot.begin(b)
        self._wait_wrist(b, timeout)

    def _wait_wrist(self, b: int, timeout: float) -> None:
        """The wrist camera's detections due at b (the gate may have been met by the head
        camera's: both share one key), when perception runs and publishes them."""
        perception = self.gate.gate.schedules.get("perception")
        cfg = self.svc.config
        due = b - self.gate.latency_ns("perception")
        publishes = WRIST in cfg.perception.cameras and WRIST in cfg.sim.cameras
        if (
            perception is None
            or "perception" not in self.gate.gate.alive
            or not (self.gate.lockstep and publishes)
            or due < 0
            or due % perception.period_ns
        ):
            return
        if not self.robot.wait_wrist(timeout):
            self.svc.log.warning("t=%.2f s: no wrist detections stamped %d", b / NS_PER_S, due)

    # -- requests and cancels -------------------------------------------------------------

    def _on_submit(self, request: MissionRequest | None, _selector: str) -> MissionReceipt:
        """A request by query (the server's thread): in the inbox before the reply goes."""
        assert request is not None  # served with a request type: Server decoded it
        self.requests.push(encode(request))
        return MissionReceipt(request_id=request.request_id)

    def _publish(self, status: MissionStatus) -> None:
        self.status_pub.put(status)
        self.log.status(status)

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

    def _requests(self, b: int) -> None:
        for payload in self.requests.drain():
            parsed = parse_request(payload)
            if isinstance(parsed, Rejection):
                self._reject(b, parsed)
                continue
            self.log.request(f"request {parsed.request_id}: {parsed.object} to {parsed.person}")
            if self.tree.busy:
                running = self.tree.request.request_id if self.tree.request else ""
                self._reject(
                    b, Rejection(parsed.request_id, "busy", f"mission {running} is running")
                )
                continue
            down = self.deps.missing()
            refused = (
                Rejection(parsed.request_id, "unavailable", f"not running: {', '.join(down)}")
                if down
                else check_request(parsed, self.robot)
            )
            if refused is not None:
                self._reject(b, refused)
                continue
            self._start(b, parsed)

    def _start(self, b: int, request: MissionRequest) -> None:
        self.tree.start(request)
        self.deps.arm()
        self.board.update(b, request.request_id, "accepted", detail="checked against the map")
        self._publish(self.board.sent(b))

    def _cancels(self) -> Outcome | None:
        outcome = None
        for payload in self.cancels.drain():
            cancel = parse_cancel(payload)
            current = self.tree.request
            if cancel is None:
                self.log.request(f"cancel ignored: not a MissionCancel: {payload[:200]!r}", True)
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

    # -- the tick -------------------------------------------------------------------------

    def tick(self, b: int) -> None:
        self._wait_inputs(b)
        self.log.at(b)
        if not self.started:  # (re)started: no request is in progress, and clients hear it
            self.started = True
            self.board.update(b, "", "idle", detail=f"mission started at t={b / NS_PER_S:.2f} s")
        self._requests(b)
        request = self.tree.request
        outcome = self._cancels()
        lost = self.deps.lost() if outcome is None and request is not None else None
        if lost is not None:
            self.svc.log.error("t=%.2f s: %s: the mission fails", b / NS_PER_S, lost)
            outcome = self.tree.fail("dependency_lost", lost)
        if outcome is None:
            try:
                outcome = self.tree.tick()
            except Exception:
                self.svc.log.exception("the tree failed at t=%.2f s", b / NS_PER_S)
                if self.tree.cancel("internal error") is None:
                    halt(self.robot, "internal error")
                outcome = Outcome("failed", "internal", "a behaviour raised: see the log")
        self.log.tree(self.tree.statuses(), self.tree.text)
        if outcome is not None and request is not None:
            self.deps.disarm()
            done = 1.0 if outcome.state == "succeeded" else self.board.status.progress
            changed = self.board.update(
                b,
                request.request_id,
                outcome.state,
                self.board.status.behaviour,
                done,
                outcome.reason,
                outcome.detail,
            )
        elif self.tree.request is not None:
            stage, leaf, progress = self.tree.where()
            changed = self.board.update(
                b, self.tree.request.request_id, "running", stage, progress, detail=leaf
            )
        else:
            changed = False
        self.robot.end(b)
        if changed or self.board.due(b):
            self._publish(self.board.sent(b))


def main(svc: Service) -> None:
    MissionNode(svc).run()
