"""The mission service: a 20 Hz lockstep participant that ticks the bring-me tree and
runs the mapping jobs (the patrol, the exploration), one job at a time.

Requests and cancels arrive as raw JSON (so a malformed one can still be answered with
its `request_id`) and wait in a queue for the loop; a request can also come as a query
(`mission/submit`), answered once it is in that queue, so a client knows it was heard.
Each tick b (multiples of `time.participants.mission.period_s`):

1. inputs as of b: the odom stamped b (50 Hz, waited for), the `wbc/status` stamped
   before b (waited for while the controller is alive), and the outputs of navigation
   and perception that take effect by b (`UpstreamGate`);
2. requests: parsed, refused at once when malformed, when a mission or a mapping job
   runs (`busy`), when a service it depends on is not running (`unavailable`) or when
   the map does not know the object or the person; else the tree starts (a fetch) or
   the mapping job (`explore`, `patrol`); cancels of the running request stop it;
3. a dependency (the sim; the WBC, navigation, perception, the map: those of
   `time.participants`) that went away or restarted since the request started fails it
   `dependency_lost` (nobody waits for the dead: noticed 0.3 s after its token went, said
   on the status at once, and held until `HOLD_S` (0.8 s) in case it comes back as the same
   process, its link only lapsed); else the tree ticks once; its outcome,
   stage and progress become the status. A dead sim stops the clock, so no tick comes:
   while the clock stands still the loop checks every `IDLE_POLL_S` wall (`Desk.stalled`) and
   fails the request `dependency_lost: sim is gone`, stamped at the last tick; a
   dependency lost while the tick awaits its inputs (a killed WBC sends no odom) ends
   the wait and fails it the same way (`TickInputs`);
4. the mapping jobs (`patrol_desk`): the patrol's requests (`mission/patrol`, a query
   answered once the loop took it; a start refused `busy` while a fetch runs), then one
   step of the running job (`patrol.PatrolRunner`, `explore.ExploreRunner`: walk
   obeying navigation, the arm in its posture, pose goals to navigation); a request's
   job then goes on `mission/status` (`Desk.job_status`);
5. published stamped b: cmd_vel from source `mission` (zero unless a behaviour drives),
   a wbc mode when asked for (by the tree or the patrol), the status on change and every
   `status_every_s`, the patrol's status (every tick, even after a failed one: the map
   waits for it, and fuses the wrist camera while it says `arm_look`); then the ack. A
   bug in a behaviour is logged with its traceback, the robot halted and the mission
   failed `internal`; the loop goes on.

A mission that (re)starts says so: its first status is `idle` with no request and the
sim time it started at, so a client whose request was in progress knows it was lost and
can send it again.

This module is wiring only: the parts are `inbox` (requests and cancels as they arrive),
`inputs` (step 1), `desk` (steps 2–3 and the status of step 5), `patrol_desk` (step 4),
`robot` (`BusRobot`: the bus as the behaviours and the patrol see it, and the tick's
cmd_vel) and `tree`.
"""

from __future__ import annotations

import msgspec

from common.lifelines import HOLD_S, Dependencies
from common.lockstep import PeriodicTicker, UpstreamGate, hear_all
from common.map_frame import MapFrame
from common.messages.base import NS_PER_S
from common.messages.mission import (
    MissionCancel,
    MissionRequest,
    MissionStatus,
    PatrolRequest,
    PatrolStatus,
)
from common.service import Service
from services.mission.algorithms import default_algorithms
from services.mission.behaviours.base import Context
from services.mission.desk import Desk
from services.mission.explore import ExploreRunner
from services.mission.inbox import Inbox, RequestInbox
from services.mission.inputs import TickInputs
from services.mission.journal import Journal
from services.mission.mission_log import MissionLogger
from services.mission.patrol import PatrolRunner
from services.mission.patrol_desk import PatrolDesk
from services.mission.requests import StatusBoard
from services.mission.robot import WRIST, BusRobot
from services.mission.tree import MissionTree

NAME = "mission"
#: Wall seconds between two looks at the dependencies while the clock stands still: a
#: loss is noticed `LOST_GRACE_S` (0.3 s) after its token went, and said within this of
#: it (the policy's 0.5 s to notice; it was 0.1 s, and a kill was said 0.45-0.63 s after).
IDLE_POLL_S = 0.02
#: The services a job depends on: the sim (the world and its clock) and the lockstep
#: participants among these.
DEPENDENCIES = ("wbc", "navigation", "perception", "semantic_map", "localization")


#: Localization samples the mission keeps (60 s at 10 Hz): a grasp plan's reaches (the
#: lift, the back-out) go to odom with the correction at its capture, seconds before.
MAP_FRAME_HISTORY = 600


class MissionNode:
    """The parts, wired from the config and the bus, and the loop; see the module docstring."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        m = cfg.mission
        self.period_s = cfg.time.period_of(NAME, 0.05)
        latency = cfg.time.latencies_ns()
        bus, keys = svc.bus, svc.keys
        self.robot = BusRobot(
            bus, keys, m.query_timeout_s, latency, m.sighting_gate_m,
            MapFrame(bus, keys, cfg, history=MAP_FRAME_HISTORY),
            (m.arm_slow_m, m.arm_slow_speed),
        )  # fmt: skip
        self.gate = UpstreamGate(bus, keys, cfg)
        self.gate.watch("navigation", self.robot.nav)
        self.gate.watch("perception", self.robot.detections)
        self.alive = bus.watch_alive(keys.alive_all)
        needed = ["sim", *(n for n in DEPENDENCIES if n in cfg.time.participants)]
        self.deps = Dependencies(self.alive.lifelines, needed, keys.alive, hold_s=HOLD_S)
        heard = {keys.alive(n) for n in self.deps.names}
        self.inputs = TickInputs(
            self.robot,
            self.gate,
            self.alive.alive,
            lambda: hear_all(self.alive, heard, m.input_timeout_s),
            keys.alive("wbc"),
            round(NS_PER_S / cfg.wbc.status_hz),
            WRIST in cfg.perception.cameras and WRIST in cfg.sim.cameras,
            m.input_timeout_s,
            svc.log,
            lost=self._dependency_lost,
            stopping=svc.stop.is_set,
            odom_alive_key=keys.alive("wbc" if cfg.odom_from_estimate() else "sim"),
        )
        self.requests = RequestInbox()
        self._subs = [bus.raw(keys.mission_request, MissionRequest, self.requests.push)]
        bus.serve(keys.mission_submit, MissionRequest, self.requests.submit)
        self.cancels = Inbox()
        self._subs.append(bus.raw(keys.mission_cancel, MissionCancel, self.cancels.push))
        self.status_pub = bus.publisher(keys.mission_status, MissionStatus, "data")
        self.log = MissionLogger(svc.rec, svc.log)
        ctx = Context(self.robot, m, default_algorithms(m), self.log.decision)
        self.tree = MissionTree(ctx)
        self.patrol = PatrolDesk(
            PatrolRunner(self.robot, m, self.log.patrol),
            self.robot,
            m,
            Dependencies(self.alive.lifelines, needed, keys.alive, hold_s=HOLD_S),
            self.log,
            svc.log,
            explorer=ExploreRunner(self.robot, m, self.log.patrol),
        )
        bus.serve(keys.mission_patrol, PatrolRequest, self.patrol.ask)
        self.patrol_pub = bus.publisher(
            keys.mission_patrol_status, PatrolStatus, "data", again=True
        )
        board = StatusBoard(round(m.status_every_s * NS_PER_S))
        self.desk = Desk(
            self.tree,
            self.robot,
            self.deps,
            board,
            self.requests,
            self.cancels,
            self.log,
            self.status_pub.put,
            svc.log,
            jobs=self.patrol,
            journal=Journal.of_run(),
        )
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_s, svc.stop)
        self.last_b = 0

    def run(self) -> None:
        self.svc.ready()
        for b in self.ticker.ticks(poll_s=IDLE_POLL_S, on_idle=self._stalled):
            self.last_b = b
            try:
                self.tick(b)
            except Exception:  # a bug: say it, stop the robot, keep serving
                self.svc.log.exception("mission tick at t=%.2f s failed", b / NS_PER_S)
            finally:
                self.patrol_pub.put(self._patrol_status(b))  # every tick: the map waits
                self.ticker.ack(b)

    def _patrol_status(self, b: int) -> PatrolStatus:
        """The jobs' status at b, saying `arm_look` too while a fetch's search holds the
        arm up (the map fuses the wrist camera then), with the robot's latest takes."""
        status = self.patrol.published(b)
        if self.tree.arm_look and not status.arm_look:
            status = msgspec.structs.replace(status, arm_look=True)
        return msgspec.structs.replace(status, taken=tuple(self.tree.ctx.taken))

    def _stalled(self) -> None:
        """No tick for a while: a request whose sim (or another dependency) is gone ends
        now, its status stamped at the last tick (the loop is the only thread here)."""
        try:
            if self.desk.stalled(self.last_b):
                self.desk.flush(self.last_b, True)
        except Exception:  # a bug: say it, keep serving
            self.svc.log.exception("mission: failing a stalled request raised")

    def _dependency_lost(self) -> bool:
        """Whether a dependency of the running request or job went away; one noticed
        gone and held for is said now (the tick may wait on its inputs for `HOLD_S`)."""
        request = self.tree.request is not None and self.desk.deps.lost() is not None
        if self.tree.request is not None and not request:
            self.desk.notice(self.last_b)
        return request or (self.patrol.job.running and self.patrol.deps.lost() is not None)

    def tick(self, b: int) -> None:
        """Inputs as of b, the desks' steps, the robot's outputs, then the status."""
        if not self.inputs.wait(b, first=not self.desk.started):
            self._stalled()  # a dependency went away while its inputs were awaited
        changed = self.desk.step(b)
        for name in self.desk.deps.take_lapses() + self.patrol.deps.take_lapses():
            self.svc.log.warning(
                "t=%.2f s: %s's link lapsed and came back as the same process: the job "
                "goes on", b / NS_PER_S, name,
            )  # fmt: skip
        request = self.tree.request
        self.patrol.step(b, f"mission {request.request_id} is running" if request else "")
        changed |= self.desk.job_status(b)
        self.robot.end(b)
        self.desk.flush(b, changed)


def main(svc: Service) -> None:
    MissionNode(svc).run()
