"""The fault battery's and the up/down trial's own parts, on real processes and files:
when a fault is injected, what the summary counts, what a run leaves behind."""

from __future__ import annotations

import argparse
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from bench import trial_faults
from bench.trial_faults import Fault, summary, verdict
from bench.trial_updown import map_state, run_processes
from common.messages import encode
from common.messages.base import NS_PER_S
from common.messages.mission import MissionStatus
from common.messages.sim import Clock


class Ctl:
    """`Supervised.ctl("pid", name)` of a stack whose service is `proc`."""

    def __init__(self, proc: subprocess.Popen[bytes]) -> None:
        self.proc = proc

    def ctl(self, *args: str) -> str:
        assert args[0] == "pid"
        return f"{self.proc.pid}\n"


def _status(behaviour: str, t_s: float) -> MissionStatus:
    return MissionStatus(stamp_ns=round(t_s * NS_PER_S), request_id="r", state="running",
                         behaviour=behaviour)  # fmt: skip


def _clock(t_s: float) -> Clock:
    return Clock(stamp_ns=round(t_s * NS_PER_S), tick=round(t_s * 1000), mode="lockstep", rtf=1.0)


def test_a_fault_waits_for_its_phase_and_its_delay_then_kills_once() -> None:
    victim = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        fault = Fault(Ctl(victim), "wbc", "approaching", signal.SIGKILL, 1.5)  # type: ignore[arg-type]
        fault.progress(_status("navigate_to_object", 1.0), _clock(1.0), True)
        fault.progress(_status("approach_object", 4.0), _clock(4.0), True)  # the phase starts
        fault.progress(_status("approach_object", 4.0), _clock(5.0), False)  # 1 s in: not yet
        assert not fault.wall and victim.poll() is None
        fault.progress(_status("approach_object", 4.0), _clock(5.5), False)
        assert victim.wait(timeout=10) == -signal.SIGKILL
        assert (fault.at, fault.sim_ns, fault.pid) == ("approach_object", 5_500_000_000, victim.pid)
        fault.progress(_status("pose_estimation", 9.0), _clock(9.0), True)  # once
        assert fault.sim_ns == 5_500_000_000 and fault.final is None
        lost = MissionStatus(stamp_ns=5_550_000_000, request_id="r", state="failed",
                             reason="dependency_lost", detail="wbc is gone")  # fmt: skip
        fault.progress(lost, _clock(5.55), True)  # its arrival, not the watch's end
        assert fault.final == lost and fault.final_wall >= fault.wall
    finally:
        if victim.poll() is None:
            victim.kill()


def _state_becomes(pid: int, states: set[str], timeout_s: float = 5.0) -> bool:
    """Whether the process's state (its /proc stat letter) is one of `states` within the
    timeout (a signal is delivered when the kernel next schedules the process)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if Path(f"/proc/{pid}/stat").read_text().split()[2] in states:
            return True
        time.sleep(0.01)
    return False


def test_a_stopped_process_is_resumed_when_the_case_ends() -> None:
    victim = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        fault = Fault(Ctl(victim), "navigation", "navigating", signal.SIGSTOP, 0.0)  # type: ignore[arg-type]
        fault.progress(_status("navigate_to_object", 0.5), _clock(0.5), True)
        assert _state_becomes(victim.pid, {"T"})  # stopped
        fault.resume()
        assert _state_becomes(victim.pid, {"S", "R"})
    finally:
        victim.kill()
        victim.wait()


def test_the_slow_consumer_joins_at_the_fault_stalls_and_goes_when_the_case_ends(
    monkeypatch: Any,
) -> None:
    """`client` with the `slow` signal: no process of the stack is signalled; a slow
    consumer starts at the fault (here a stand-in that sleeps) and is killed at the end;
    the longest wall gap between clocks after the fault is kept."""
    started: list[list[str]] = []
    real = subprocess.Popen

    def popen(args: list[str], **kw: Any) -> subprocess.Popen[bytes]:
        started.append(list(args))
        return real([sys.executable, "-c", "import time; time.sleep(60)"])

    monkeypatch.setattr(subprocess, "Popen", popen)

    stack = argparse.Namespace(env=dict(os.environ))  # what the fault reads of its stack
    fault = Fault(stack, "client", "navigating", 0, 0.0)  # type: ignore[arg-type]
    fault.progress(_status("navigate_to_object", 0.5), _clock(0.5), True)
    assert started and started[0][1:3] == ["-m", "bench.slow_consumer"]
    consumer = fault.consumer
    assert consumer is not None and consumer.poll() is None and fault.pid == consumer.pid
    time.sleep(0.3)  # no clock for 0.3 s: the world stalled that long
    fault.progress(_status("navigate_to_object", 0.5), _clock(0.6), False)
    fault.progress(_status("navigate_to_object", 0.5), _clock(0.7), False)
    assert 0.25 < fault.clock_stall_s < 5.0
    fault.resume()
    assert consumer.poll() is not None


def test_the_battery_pairs_the_slow_consumer_with_slow_only(monkeypatch: Any) -> None:
    ran: list[tuple[str, str]] = []

    def case(service: str, phase: str, seed: int, how: str, _o: Any) -> dict[str, Any]:
        ran.append((service, how))
        return {"service": service, "phase": phase, "signal": how, "seed": seed}

    monkeypatch.setattr(trial_faults, "run_case", case)
    trial_faults.run_faults(["wbc", "client"], ["navigating"], ["kill", "slow"], 1, {})
    assert ran == [("wbc", "kill"), ("client", "slow")]


def test_the_summary_counts_hung_cases_silent_drops_and_falls_the_wbc_survived() -> None:
    cases: list[dict[str, Any]] = [
        {"injected": True, "service": "wbc", "signal": "kill", "ended_s": 0.1,
         "reported_s": 2.1, "noticed_s": 0.1, "hung": False, "fell": True, "map_ok": True,
         "final": "failed dependency_lost: wbc is gone"},
        {"injected": True, "service": "navigation", "signal": "kill", "ended_s": 0.2,
         "reported_s": 12.0, "noticed_s": 12.0, "hung": True, "fell": False, "dropped": True,
         "drop_reported": False, "map_ok": True,
         "final": "failed dependency_lost: navigation is gone"},
        {"injected": True, "service": "perception", "signal": "stop", "ended_s": 0.3,
         "reported_s": 2.3, "noticed_s": 0.3, "hung": False, "fell": True, "map_ok": False,
         "final": "failed dependency_lost: perception is gone"},
        {"injected": True, "service": "mission", "signal": "kill", "ended_s": 4.0,
         "reported_s": 4.0, "hung": False, "map_ok": True,
         "final": "failed dependency_lost: mission restarted"},
        {"injected": False, "service": "sim", "signal": "kill", "map_ok": True},
    ]  # fmt: skip
    s = summary(cases)
    assert (s["cases"], s["injected"], s["hung"], s["silent_drops"]) == (5, 4, 1, 1)
    assert (s["falls"], s["falls_wbc_alive"], s["map_ok"]) == (2, 1, "4/5")
    assert s["ended_p50_s"] == 0.25 and s["reported_p95_s"] is not None
    # what the policy's 0.5 s is about: the dependents' notice, not the mission's restart
    assert (s["detected"], s["detected_p50_s"], s["detected_max_s"]) == (3, 0.3, 12.0)


def test_a_loss_is_noticed_at_the_first_status_that_holds_for_the_hurt_service() -> None:
    fault = Fault(None, "wbc", "carrying", signal.SIGKILL, 0.0)  # type: ignore[arg-type]
    fault.wall = 10.0
    said = [
        (9.0, MissionStatus(stamp_ns=1, request_id="r", state="running", detail="holding: wbc")),
        (10.1, MissionStatus(stamp_ns=2, request_id="x", state="failed")),  # another request
        (10.2, MissionStatus(stamp_ns=3, request_id="r", state="running", detail="walk")),
        (
            10.4,
            MissionStatus(
                stamp_ns=4, request_id="r", state="running", detail="holding: wbc not heard (walk)"
            ),
        ),
        (12.4, MissionStatus(stamp_ns=5, request_id="r", state="failed")),
    ]
    fault.heard = [(t, encode(s)) for t, s in said] + [(10.3, b"\x00garbage")]
    assert fault.noticed_s("r") == pytest.approx(0.4)
    fault.heard = [(t, encode(s)) for t, s in said if s.stamp_ns != 4]
    assert fault.noticed_s("r") == pytest.approx(2.4)  # none held: the final one
    fault.service = "navigation"
    fault.heard = [(t, encode(s)) for t, s in said[:4]]
    assert fault.noticed_s("r") is None  # it held for another service


def test_a_frozen_mission_or_router_is_mute_not_hung_and_a_late_end_is_hung() -> None:
    stop, kill = signal.SIGSTOP, signal.SIGKILL
    # the client's own dependency_lost ended it at once; the frozen mission said nothing
    assert verdict("mission", stop, 0.5, None) == {"mute": True, "hung": False}
    assert verdict("router", stop, 0.6, None) == {"mute": True, "hung": False}
    # a killed mission is restarted and must report the request it held
    assert verdict("mission", kill, 0.5, None) == {"mute": False, "hung": True}
    assert verdict("navigation", stop, 0.5, 0.5) == {"mute": False, "hung": False}
    assert verdict("navigation", stop, 0.5, 11.0)["hung"]
    assert verdict("mission", stop, 12.0, None)["hung"]  # the client knew too late
    assert not verdict("client", 0, 120.6, 120.6)["hung"]  # a slow consumer's fetch goes on


def test_a_runs_processes_are_found_by_its_folder(tmp_path: Path) -> None:
    env = dict(os.environ, DUME_RUN_DIR=str(tmp_path))
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"], env=env)
    try:
        assert run_processes(tmp_path) == [f"{sleeper.pid} {sys.executable}"]
        assert run_processes(tmp_path / "other") == []
    finally:
        sleeper.kill()
        sleeper.wait()
    assert not any(f.startswith(f"{sleeper.pid} ") for f in run_processes(tmp_path))


def test_a_map_database_is_checked_and_its_lock_files_named(tmp_path: Path) -> None:
    db = tmp_path / "m.sqlite"
    assert map_state(db) == ("no file", -1, [])
    con = sqlite3.connect(db)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("CREATE TABLE entities (id TEXT)")
    con.executemany("INSERT INTO entities VALUES (?)", [("a",), ("b",)])
    con.commit()
    ok, count, locks = map_state(db)  # open: its WAL is there
    assert (ok, count) == ("ok", 2) and "m.sqlite-wal" in locks
    con.close()
    assert map_state(db) == ("ok", 2, [])  # closed cleanly: no lock files left


def test_a_request_that_went_on_after_the_router_came_back_is_not_hung() -> None:
    kill = signal.SIGKILL
    # every service reconnected as the same process; the fetch went on 12 s later
    assert verdict("router", kill, 90.0, 90.0, went_on_s=12.0) == {"mute": False, "hung": False}
    assert verdict("router", kill, 90.0, 90.0)["hung"]  # it never went on: hung
    assert verdict("navigation", kill, 90.0, 90.0, went_on_s=12.0)["hung"]  # not the router
    s = summary(
        [
            {
                "injected": True,
                "service": "router",
                "signal": "kill",
                "ended_s": 90.0,
                "reported_s": 90.0,
                "went_on_s": 12.0,
                "hung": False,
                "map_ok": True,
            }
        ]
    )
    assert (s["went_on"], s["went_on_max_s"], s["hung"]) == (1, 12.0, 0)
