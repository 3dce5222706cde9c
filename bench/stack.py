"""`dume bench stack`: the whole stack on the demo's world, measured.

Every service as a process (hall, seed 0, the demo's settings: lockstep, the recording
on, start-gated), and the demo's request. After `WARMUP_S` of sim time (start-up, the
first plans) it measures for `sim_s` seconds of sim time, or to the request's end with
`full`, and prints:

- per service (the router too): CPU seconds per sim second (`/proc/<pid>/stat`), and
  the share of the wall time the sim waited for it (lockstep's critical path: the sim
  books each wait to the participant that answered last, `SimStats.waited_s`);
- the real-time factor (sim seconds per wall second);
- the bare costs, per sim second, measured in the same run: physics (`SimStats.step_s`),
  each camera's rendering (`render_s`), the WBC's tick (`WbcStatus.tick_us`, the median ×
  its rate), the network's forward (`Detections.segment_ms` × the frames); and from them
  the ideal real-time factor for this machine: the sim and the WBC alternate every
  command period, so physics + the WBC's tick are one serial chain (the cameras render
  on a thread of their own, `services.sim.render_worker`), and everything bare shares
  the machine's cores: ideal = min(1 / serial, cores / total).
  `measured_over_ideal` says how much of it the stack reaches (the rest is transport,
  encoding, recording, Python glue and waiting);
- the WBC's tick p50/p99 (every status's tick: a sample of one tick in ten), the sim's
  publishing cost, and the recording's size.

JSON on the last line. Quote medians of three runs on a quiet machine.
"""

from __future__ import annotations

import os
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.eval.run import read_map, start_gate_overrides, watch_mission
from bench.eval.targets import demo_pair
from common.bus import Latest
from common.config import Overrides, merged
from common.keys import SERVICES
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.perception import Detections
from common.messages.sim import Clock, SimStats
from common.messages.wbc import WbcStatus
from common.recording import run_dir
from deploy.stack import ProcessStack

#: Sim seconds left out at the start (the stack settling, the first plan and map).
WARMUP_S = 5.0
#: The WBC's command rate, Hz (one tick per state it answers).
WBC_HZ = 500.0
_CLK_TCK = os.sysconf("SC_CLK_TCK")


def stack_settings(seed: int = 0) -> dict[str, Any]:
    """The demo's stack: hall, `seed`, lockstep, recording on, a fresh map."""
    return merged(
        {
            "sim.world": "hall",
            "sim.world_seed": seed,
            "time.mode": "lockstep",
            "recording.enabled": True,
            "semantic_map.start": "seed-from-world",
            "semantic_map.name": "bench-stack",
            "semantic_map.reset": True,
        },
        start_gate_overrides(),
    )


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far (its threads included)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _CLK_TCK


@dataclass
class Mark:
    """One sample: the clock, the sim's stats, every process's CPU seconds."""

    sim_s: float
    stats: SimStats
    cpu: dict[str, float]


@dataclass
class Window:
    """What the probes saw between the two marks."""

    start: Mark | None = None
    end: Mark | None = None
    wbc: list[WbcStatus] = field(default_factory=list)
    dets: list[Detections] = field(default_factory=list)


def figures(w: Window, cores: int) -> dict[str, Any]:
    """The bench's figures from a measured window (module docstring)."""
    a, b = w.start, w.end
    assert a is not None and b is not None
    sim = b.sim_s - a.sim_s
    wall = b.stats.wall_s - a.stats.wall_s
    cpu = {n: round((b.cpu[n] - a.cpu[n]) / sim, 3) for n in b.cpu}

    def per_sim_s(get: Any) -> float:
        return (get(b.stats) - get(a.stats)) / sim

    waited = {
        n: round((b.stats.waited_s.get(n, 0.0) - a.stats.waited_s.get(n, 0.0)) / wall, 3)
        for n in sorted(set(b.stats.waited_s) | set(a.stats.waited_s))
    }
    step = per_sim_s(lambda s: s.step_s)
    render = {
        c: round(per_sim_s(lambda s, c=c: s.render_s.get(c, 0.0)), 4) for c in b.stats.render_s
    }
    ticks = sorted(s.tick_us for s in w.wbc if s.tick_us > 0.0)
    qp = [s.qp_time_us for s in w.wbc]
    wbc_tick = statistics.median(ticks) * 1e-6 * WBC_HZ if ticks else 0.0
    forward = sum(d.segment_ms for d in w.dets) * 1e-3 / sim
    serial = step + wbc_tick
    total = serial + sum(render.values()) + forward
    ideal = min(1.0 / serial, cores / total) if serial > 0 else float("inf")
    rtf = sim / wall
    return {
        "sim_s": round(sim, 1),
        "wall_s": round(wall, 1),
        "rtf": round(rtf, 3),
        "ideal_rtf": round(ideal, 3),
        "measured_over_ideal": round(rtf / ideal, 3),
        "cores": cores,
        "cpu_s_per_sim_s": cpu,
        "cpu_total": round(sum(cpu.values()), 3),
        "sim_waited_share": waited,
        "bare_s_per_sim_s": {
            "physics": round(step, 4),
            "render": render,
            "wbc_tick": round(wbc_tick, 4),
            "network_forward": round(forward, 4),
        },
        "sim_publish_s_per_sim_s": round(per_sim_s(lambda s: s.publish_s), 4),
        "captures_per_sim_s": {
            c: round(per_sim_s(lambda s, c=c: s.captures.get(c, 0)), 2) for c in b.stats.captures
        },
        "wbc_tick_us": {
            "p50": round(statistics.median(ticks), 1) if ticks else None,
            "p99": round(ticks[int(0.99 * (len(ticks) - 1))], 1) if ticks else None,
            "samples": len(ticks),
        },
        "wbc_qp_us_p50": round(statistics.median(qp), 1) if qp else None,
    }


def _recording_mb(folder: Path) -> float:
    """The run's recording so far (every service's `.rrd` in `folder`), MB; 0 without one."""
    return round(sum(p.stat().st_size for p in folder.glob("*.rrd")) / 1e6, 1)


def bench_stack(overrides: Overrides, sim_s: float = 60.0, full: bool = False) -> dict[str, Any]:
    """One measured run (module docstring); its figures."""
    cores = len(os.sched_getaffinity(0))
    settings = merged(stack_settings(), overrides)
    w = Window()
    stop_at = WARMUP_S + sim_s
    with ProcessStack(list(SERVICES), settings) as stack:
        bus, keys = stack.bus, stack.keys
        stats: Latest[SimStats] = bus.latest(keys.sim_stats, SimStats)
        wbc = bus.fifo(keys.wbc_status, WbcStatus, maxlen=1 << 20)
        dets = bus.fifo(keys.detections, Detections, maxlen=1 << 16)
        pids = {n: p.pid for n, p in stack.procs.items()}

        def mark(clock: Clock) -> Mark | None:
            st = stats.get()
            if st is None:
                return None
            return Mark(clock.stamp_ns / 1e9, st, {n: cpu_s(pid) for n, pid in pids.items()})

        def on_progress(_status: MissionStatus | None, clock: Clock, _changed: bool) -> None:
            t = clock.stamp_ns / 1e9
            if w.start is None and t >= WARMUP_S:
                w.start = mark(clock)
                for fifo in (wbc, dets):  # what came before the window
                    list(fifo.drain())
            elif w.start is not None and (full or t <= stop_at):
                w.end = mark(clock)
                w.wbc.extend(wbc.drain())
                w.dets.extend(dets.drain())

        arts, people = read_map(bus)
        pair = demo_pair(arts, people)
        request = MissionRequest(request_id="bench-stack", object=pair.object, person=pair.person)
        timeout = 600.0 if full else stop_at + 0.5
        print(
            f"dume bench stack: {pair.object} for {pair.person}, "
            + ("the whole request" if full else f"{sim_s:.0f} sim s after {WARMUP_S:.0f}"),
            file=sys.stderr,
            flush=True,
        )
        record = watch_mission(bus, keys, request, timeout, on_progress, start_gate=True)
        recording = run_dir(stack.config.recording, stack.run_id)
    if w.start is None or w.end is None or w.end.sim_s <= w.start.sim_s:
        return {"error": f"no measured window (the run ended at {record.end_ns / 1e9:.1f} s)"}
    out = figures(w, cores)
    final = record.changes[-1] if record.changes else None
    out["mission"] = final.state if final else "none"
    out["recording_mb"] = _recording_mb(recording)
    return out
