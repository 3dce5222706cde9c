"""`dume trial faults`: the fault battery. Each case brings up the stack `dume demo`
brings up (supervisord, every service, lockstep, the small world from its saved map,
start-gated), asks for what the demo asks (`demo_pair`), and when the mission has been in the case's
phase for a seeded 0–2 s of sim time, hurts one process: SIGKILL (dead) or SIGSTOP
(hung, resumed only when the case ends). Then it watches, as a client and on the sim's
truth, what the failure policy promises (README, "Nobody waits for the dead"):

- **ended_s**: wall seconds from the fault until the client knows the request is over:
  a final status for it (when it arrived), or the watch's own `dependency_lost` when the
  mission or the sim itself went (`bench.eval.run.watch_mission`);
- **reported_s**: until the mission said so on `mission/status` by the request's id (a
  restarted mission reports the request it held: `services/mission/journal.py`);
- **noticed_s**: until the mission first said it holds for the hurt service ("holding:
  wbc not heard", `services/mission/desk.py`: it waits `HOLD_S` for the same process to
  come back before it fails the request) or reported the request (the policy's 0.5 s to
  notice a loss: the battery's `detected_*`);
- **went_on_s**: until the request was heard running again a sim second past the fault
  (a killed router: back, every service reconnected, and the request goes on);
- **hung**: the client did not know the request was over within `HUNG_S`, or the
  mission could speak and did not report it within `HUNG_S`. A SIGSTOPped mission or
  router cannot speak (nobody can reach a frozen mission, nor anything through a frozen
  router): there the client's own `dependency_lost` is the end, and the case is
  **mute**, not hung; the slow consumer ends nothing, and is never hung;
- **restart_s**: until the hurt service was alive again (supervisord restarts all but
  the sim); **world_restarted**: a new sim process came up under the run (never
  allowed; a SIGSTOPped sim is the same process, frozen);
- **fell**: the base's lowest height after the fault under `FALL_Z_M` (truth);
- **dropped** / **drop_reported**: an `ObjectDropped` event after the fault, and whether
  a status after it says what the robot held;
- **map_ok**: the map's SQLite file after the stack stopped: `PRAGMA integrity_check`
  and its entity count against the count before the fault.

Phases are the mission's stages: navigating (navigate_to_object), approaching
(approach_object), grasping (pick_object), carrying (bring_to_user), handing over
(release_object). A request that ends (or fails) before its phase comes is a case that
did not happen: `injected` false. The router is a target too: every session loses it.
So is a **slow consumer** (`--services client --signals slow`): a client subscribed to
everything the robot publishes that stalls `SLOW_S` in its first callback
(`bench/slow_consumer.py`); nothing of the stack is hurt, and the case measures what its
stall costs the robot: **clock_stall_s**, the longest wall gap between two sim clocks
after it started (the lockstep world stalls when the router holds back the sim's
samples), whether the request still ends well, and falls.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from bench.eval.judge import TERMINAL
from bench.eval.run import read_map, watch_mission
from bench.eval.targets import demo_pair
from bench.trial_updown import map_state
from common.bus import AliveWatch, Fifo
from common.config import REPO_ROOT, Overrides, merged
from common.keys import WORLD_EVENTS, RobotKeys
from common.messages import PayloadError, decode
from common.messages.base import NS_PER_S
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.sim import Clock, ObjectDropped, StateTruth, WorldEvents
from common.recording import new_run_id
from deploy.demo import SERVICES, demo_overrides
from deploy.stack import Supervised
from services.semantic_map.store import database_path, remove_database

Figures = dict[str, Any]

PHASES = {
    "navigating": "navigate_to_object",
    "approaching": "approach_object",
    "grasping": "pick_object",
    "carrying": "bring_to_user",
    "handing_over": "release_object",
}
SIGNALS = {"kill": signal.SIGKILL, "stop": signal.SIGSTOP, "slow": 0}
#: `client`: the slow consumer (module docstring), hurt by the `slow` "signal" only.
TARGETS = (*SERVICES, "router", "client")
#: The processes of the stack itself (a fault elsewhere hurts none of them).
STACK = frozenset({*SERVICES, "router"})
#: Wall seconds the slow consumer stalls in its first callback.
SLOW_S = 5.0
#: Sim seconds the mission has for the whole request.
TIMEOUT_S = 300.0
#: Wall seconds after the fault within which the request must have a final status.
HUNG_S = 10.0
#: Wall seconds the case waits for a restarted service, and watches after the end.
RESTART_WAIT_S = 30.0
AFTER_S = 3.0
#: A base lower than this (m, truth) has fallen; the B1 stands at 0.53 m.
FALL_Z_M = 0.3


class Fault:
    """The fault of one case, injected once from the watch's progress callback."""

    def __init__(self, stack: Supervised, service: str, phase: str, sig: int, delay_s: float):
        self.stack, self.service, self.phase, self.sig = stack, service, phase, sig
        self.delay_ns = round(delay_s * NS_PER_S)
        self.entered_ns: int | None = None
        self.pid = 0
        self.wall = 0.0  # perf_counter at the fault; 0: not yet
        self.sim_ns = 0
        self.at = ""  # the stage running when it was injected
        self.final: MissionStatus | None = None  # the request's final status, after it
        self.final_wall = 0.0  # perf_counter when it arrived
        #: perf_counter when the request was first heard running again after the fault,
        #: its clock a sim second on (a router back: every service reconnected)
        self.went_on_wall = 0.0
        self.clock_ns, self.clock_wall, self.clock_stall_s = 0, 0.0, 0.0
        self.consumer: subprocess.Popen[bytes] | None = None
        #: Every mission status as it arrived: (perf_counter, payload), decoded later;
        #: the subscriber that hears them, kept while the case runs.
        self.heard: list[tuple[float, bytes]] = []
        self.listening: Any = None

    def hear(self, payload: bytes) -> None:
        """A mission status, on Zenoh's thread: kept with when it came."""
        self.heard.append((time.perf_counter(), payload))

    def noticed_s(self, request_id: str) -> float | None:
        """Wall seconds from the fault to the first status of `request_id` after it
        that holds for the hurt service or ends the request (module docstring)."""
        for wall, payload in list(self.heard):
            if wall < self.wall:
                continue
            with contextlib.suppress(PayloadError):
                s = decode(payload, MissionStatus)
                said = s.state in TERMINAL or s.detail.startswith(f"holding: {self.service}")
                if s.request_id == request_id and said:
                    return wall - self.wall
        return None

    def progress(self, status: MissionStatus | None, clock: Clock, _changed: bool) -> None:
        if self.wall and status is not None and status.state in TERMINAL and not self.final:
            # when it arrived: the watch itself returns only after a grace of sim time,
            # which a stalled clock (a dead WBC: the sim waits for its commands) holds up
            self.final, self.final_wall = status, time.perf_counter()
        if self.wall:  # the longest wall gap between two clocks since the fault
            now = time.perf_counter()
            on = status is not None and status.state == "running" and not self.went_on_wall
            if on and clock.stamp_ns >= self.sim_ns + NS_PER_S:
                self.went_on_wall = now
            if clock.stamp_ns > self.clock_ns:
                self.clock_stall_s = max(self.clock_stall_s, now - self.clock_wall)
                self.clock_ns, self.clock_wall = clock.stamp_ns, now
        if self.wall or status is None or status.state != "running":
            return
        if status.behaviour == PHASES[self.phase] and self.entered_ns is None:
            self.entered_ns = status.stamp_ns
        if self.entered_ns is not None and clock.stamp_ns >= self.entered_ns + self.delay_ns:
            self.inject(status.behaviour, clock.stamp_ns)

    def inject(self, stage: str, sim_ns: int) -> None:
        if self.service == "client":  # the slow consumer joins the stack
            self.consumer = subprocess.Popen(
                [sys.executable, "-m", "bench.slow_consumer", "--stall", str(SLOW_S)],
                cwd=REPO_ROOT,
                env=self.stack.env,
                stdout=subprocess.DEVNULL,
            )
            self.pid = self.consumer.pid
        else:
            self.pid = int(self.stack.ctl("pid", self.service).strip() or 0)
            if self.pid <= 0:
                return
            os.kill(self.pid, self.sig)
        self.wall, self.sim_ns, self.at = time.perf_counter(), sim_ns, stage
        self.clock_ns, self.clock_wall = sim_ns, self.wall

    def resume(self) -> None:
        """A stopped process goes on (so that the stack can stop); the slow consumer goes."""
        if self.consumer is not None:
            self.consumer.kill()
            self.consumer.wait()
        elif self.wall and self.sig == signal.SIGSTOP:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGCONT)


def _lowest(truth: Fifo[StateTruth], after_ns: int, low: float) -> float:
    for s in truth.drain():
        if s.stamp_ns >= after_ns:
            low = min(low, float(s.base_position_in_world[2]))
    return low


def run_case(service: str, phase: str, seed: int, how: str, overrides: Overrides) -> Figures:
    """One case on a fresh supervised stack (see the module docstring)."""
    delay_s = float(np.random.default_rng([seed, len(service), len(phase)]).uniform(0.0, 2.0))
    out: Figures = {"service": service, "phase": phase, "signal": how, "seed": seed,
                    "delay_s": round(delay_s, 2), "injected": False}  # fmt: skip
    run_id = new_run_id()
    map_name = f"faults-{run_id}"
    args = argparse.Namespace(world="small", world_seed=0, map="saved", set=[])
    settings = merged(demo_overrides(args, map_name), {"recording.enabled": False}, overrides)
    stack = Supervised(settings, run_id=run_id)
    db = database_path(stack.config.semantic_map, map_name)
    fault = Fault(stack, service, phase, SIGNALS[how], delay_s)
    try:
        stack.start()
        stack.wait_ready(list(SERVICES), timeout_s=300.0)
        bus, keys = stack.bus, stack.keys
        statuses = bus.fifo(keys.mission_status, MissionStatus, maxlen=1 << 16)
        fault.listening = bus.raw(keys.mission_status, MissionStatus, fault.hear)
        truth = bus.fifo(keys.state_truth, StateTruth, maxlen=1 << 18)
        events = bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=1 << 16)
        _, before, _ = map_state(db)
        pair = demo_pair(*read_map(bus))  # what `dume demo` asks for
        request = MissionRequest(request_id=f"fault-{seed}", object=pair.object, person=pair.person)
        record = watch_mission(bus, keys, request, TIMEOUT_S, fault.progress, start_gate=True)
        ended = fault.final_wall or time.perf_counter()
        out |= {"ended": record.ended or (record.changes[-1].state if record.changes else "")}
        if not fault.wall:
            out["outcome"] = (
                f"{record.changes[-1].state} {record.changes[-1].reason} before the phase"
                if record.changes else record.ended
            )  # fmt: skip
            return out
        out |= {"injected": True, "at": fault.at, "at_sim_s": round(fault.sim_ns / NS_PER_S, 2),
                "ended_s": round(ended - fault.wall, 3)}  # fmt: skip
        out |= _watch_after(stack, keys, fault, request, statuses, truth, events, before)
        noticed = fault.noticed_s(request.request_id)
        out["noticed_s"] = None if noticed is None else round(noticed, 3)
        went_on = round(fault.went_on_wall - fault.wall, 3) if fault.went_on_wall else None
        out["went_on_s"] = went_on
        out |= verdict(fault.service, fault.sig, out["ended_s"], out["reported_s"], went_on)
        out["clock_stall_s"] = round(fault.clock_stall_s, 2)
    finally:
        fault.resume()
        stack.stop(timeout_s=180.0)
        ok, count, _ = map_state(db)
        out |= {"map_ok": ok == "ok", "map_entities": count}
        remove_database(db)
    return out


def _watch_after(
    stack: Supervised,
    keys: RobotKeys,
    fault: Fault,
    request: MissionRequest,
    statuses: Fifo[MissionStatus],
    truth: Fifo[StateTruth],
    events: Fifo[WorldEvents],
    map_before: int,
) -> Figures:
    """After the watch ended: the mission's report, the restart, falls and drops."""
    rid = request.request_id
    final = fault.final
    said: list[MissionStatus] = [] if final is None else [final]
    reported = None if final is None else fault.final_wall - fault.wall
    restarted = None
    low = np.inf
    deadline = time.perf_counter() + RESTART_WAIT_S
    alive_key = keys.alive(fault.service) if fault.service != "client" else ""
    watch = stack.bus.watch_alive(keys.alive_all)  # the token of a restarted one: at once
    while time.perf_counter() < deadline:
        statuses.wait(0.05)
        now = time.perf_counter()
        for s in statuses.drain():
            if s.request_id == rid and s.stamp_ns >= fault.sim_ns:
                said.append(s)
            if final is None and s.request_id == rid and s.state in TERMINAL:
                final, reported = s, now - fault.wall
        low = _lowest(truth, fault.sim_ns, low)
        restarts = fault.service not in ("sim", "client")  # nothing restarts either
        if restarted is None and restarts and _alive(stack, alive_key, fault, watch):
            restarted = now - fault.wall
        if final is not None and (restarted is not None or not restarts):
            break
    watch.undeclare()
    time.sleep(AFTER_S)
    low = _lowest(truth, fault.sim_ns, low)
    drops = [e for b in events.drain() for e in b.events
             if isinstance(e, ObjectDropped) and e.stamp_ns >= fault.sim_ns]  # fmt: skip
    last = said[-1] if said else None
    return {
        "final": None if final is None else f"{final.state} {final.reason}: {final.detail}",
        "reported_s": None if reported is None else round(reported, 3),
        "restart_s": None if restarted is None else round(restarted, 2),
        "world_restarted": fault.service == "sim" and _new_process(stack, fault),
        "lowest_z_m": None if not np.isfinite(low) else round(float(low), 3),
        "fell": bool(np.isfinite(low) and low < FALL_Z_M),
        "dropped": bool(drops),
        "drop_reported": bool(drops) and last is not None and "was holding" in last.detail,
        "map_before": map_before,
    }


def verdict(
    service: str,
    sig: int,
    ended_s: float,
    reported_s: float | None,
    went_on_s: float | None = None,
) -> Figures:
    """Whether the case is mute (the mission cannot speak) and hung (module docstring).
    A fault on no service of the stack (the slow consumer, a client of its own: `sig`
    0, no signal) hurts nothing the request depends on: nothing is to be detected, the
    request goes on as it would, and a long one is no hang. Nor is a request heard
    running again after the router was killed (`went_on_s`, reported as its own figure:
    the world held that long): supervisord restarted it, every service reconnected as
    the same process, and the mission went on (`common.lifelines`: a lapse of the link
    to them all)."""
    if service not in STACK or sig == 0:
        return {"mute": False, "hung": False}
    if service == "router" and went_on_s is not None:
        return {"mute": False, "hung": False}
    mute = sig == signal.SIGSTOP and service in ("mission", "router")
    unreported = reported_s is None or reported_s > HUNG_S
    return {"mute": mute, "hung": ended_s > HUNG_S or (unreported and not mute)}


def _new_process(stack: Supervised, fault: Fault) -> bool:
    """The hurt service runs again, as a process other than the one hurt."""
    if "RUNNING" not in stack.ctl("status", fault.service):
        return False
    pid = stack.ctl("pid", fault.service).strip()
    return pid.isdigit() and int(pid) not in (0, fault.pid)


def _alive(stack: Supervised, key: str, fault: Fault, watch: AliveWatch) -> bool:
    """The hurt service is alive again: its token is back (the watch hears it at once; a
    liveliness query can take seconds under load) from a new process (a stopped one
    never is)."""
    if fault.service == "router":
        return "RUNNING" in stack.ctl("status", "router") and bool(stack.alive())
    return key in watch.alive() and _new_process(stack, fault)


def summary(cases: Sequence[Figures]) -> Figures:
    """The battery's figures over its injected cases."""
    done = [c for c in cases if c.get("injected")]
    detect = [c["ended_s"] for c in done if c.get("ended_s") is not None]
    noticed = [c["noticed_s"] for c in done if _noticed_by_dependents(c)]
    reported = [c["reported_s"] for c in done if c.get("reported_s") is not None]
    went_on = [c["went_on_s"] for c in done if c.get("went_on_s") is not None]
    survived = [c for c in done if c["service"] != "wbc" or c["signal"] != "kill"]
    return {
        "cases": len(cases),
        "injected": len(done),
        "hung": sum(bool(c.get("hung")) for c in done),
        "mute": sum(bool(c.get("mute")) for c in done),
        "silent_drops": sum(bool(c.get("dropped")) and not c.get("drop_reported") for c in done),
        "falls": sum(bool(c.get("fell")) for c in done),
        "falls_wbc_alive": sum(bool(c.get("fell")) for c in survived),
        "map_ok": f"{sum(bool(c.get('map_ok')) for c in cases)}/{len(cases)}",
        "world_restarted": sum(bool(c.get("world_restarted")) for c in done),
        "ended_p50_s": _q(detect, 50), "ended_p95_s": _q(detect, 95),
        "reported_p50_s": _q(reported, 50), "reported_p95_s": _q(reported, 95),
        "detected": len(noticed), "detected_p50_s": _q(noticed, 50),
        "detected_p95_s": _q(noticed, 95), "detected_max_s": max(noticed) if noticed else None,
        "went_on": len(went_on), "went_on_max_s": max(went_on) if went_on else None,
    }  # fmt: skip


def _noticed_by_dependents(case: Figures) -> bool:
    """A case the policy's 0.5 s to notice a loss is about: a service the mission depends
    on (not the mission itself, whose restart reports what it held; not the router,
    whose world goes on; not a client of our own), gone and said gone by the mission."""
    return (
        case.get("service") in STACK - {"mission", "router"}
        and case.get("noticed_s") is not None
        and "dependency_lost" in str(case.get("final"))
    )


def _q(xs: Sequence[float], q: float) -> float | None:
    return round(float(np.percentile(xs, q)), 3) if xs else None


def run_faults(
    services: Sequence[str], phases: Sequence[str], signals: Sequence[str], seeds: int,
    overrides: Overrides,
) -> Figures:  # fmt: skip
    """Every service × phase × signal × seed; one line per case on stderr as it ends."""
    cases: list[Figures] = []
    for seed in range(seeds):
        for how in signals:
            for service in services:
                if (service == "client") != (how == "slow"):
                    continue  # the slow consumer is no process to signal, nor slow itself
                for phase in phases:
                    case = run_case(service, phase, seed, how, overrides)
                    cases.append(case)
                    print(_line(case), file=sys.stderr, flush=True)
    return {"trial": "faults", "summary": summary(cases), "cases": cases}


def _line(c: Figures) -> str:
    head = f"{c['signal']:4} {c['service']:12} {c['phase']:12} seed {c['seed']}"
    if not c.get("injected"):
        return f"{head}: not injected ({c.get('outcome', '')})"
    return (
        f"{head} at {c['at']} t={c['at_sim_s']} s: ended {c['ended_s']} s, reported "
        f"{c.get('reported_s')} s ({c.get('final')}), restart {c.get('restart_s')} s, "
        f"lowest z {c.get('lowest_z_m')} m, clock stalled {c.get('clock_stall_s')} s, "
        f"dropped {c.get('dropped')}, map ok "
        f"{c.get('map_ok')} ({c.get('map_before')} → {c.get('map_entities')})"
    )
