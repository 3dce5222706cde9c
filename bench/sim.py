"""`dume bench sim`: what one simulated tick costs, bare and over Zenoh in lockstep.

- `mj_step` µs in the small and hall worlds, robot standing under the PD stand-hold.
- render ms per camera (RGB + depth + segmentation, 320 × 240, shadows and MSAA off).
- ticks/s of a bare in-process loop (state → the same PD hold law → command → step) and
  of the lockstep stack (sim and `hold` as separate processes over a Zenoh router), with
  their ratio, measured in the same run. Cameras are off in both loops so the ratio is
  the transport's cost; the lockstep figure with cameras on is reported beside it.
"""

from __future__ import annotations

import logging
import statistics
import time
from typing import Any

import numpy as np

from bench.lockstep import commander, lockstep_rate
from common.config import Overrides, merged
from common.messages import as_numpy
from services.sim.cameras import CameraRig
from services.sim.core import SimCore
from services.sim.hold import StandHold
from services.sim.world import generate_world

log = logging.getLogger(__name__)


def _median_us(samples: list[float]) -> float:
    return round(statistics.median(samples) * 1e6, 1)


def step_cost(world_name: str, steps: int = 2000) -> dict[str, float]:
    core = SimCore(generate_world(0, world_name))
    law = StandHold()
    mj, full = [], []
    for tick in range(steps):
        t0 = time.perf_counter()
        core.robot_state(tick)
        core.command(law.tau_ff, law.q_des, law.v_des, law.kp, law.kd, core.time_ns)
        t1 = time.perf_counter()
        core.step()
        t2 = time.perf_counter()
        mj.append(t2 - t1)
        full.append(t2 - t0)
    return {"mj_step_us_p50": _median_us(mj), "tick_us_p50": _median_us(full)}


def render_cost(frames: int = 20) -> dict[str, float]:
    core = SimCore(generate_world(0, "hall"))
    rig = CameraRig(core.model, 320, 240)
    out = {}
    for cam in ("camera_head", "camera_wrist"):
        times = []
        for k in range(frames):
            t0 = time.perf_counter()
            rig.capture(core.data, cam, k)
            times.append(time.perf_counter() - t0)
        out[f"render_ms_p50_{cam}"] = round(statistics.median(times) * 1e3, 2)
    return out


def bare_loop(sim_s: float, world_name: str = "small") -> float:
    """Ticks per wall second of the in-process reference loop."""
    core = SimCore(generate_world(0, world_name))
    law = StandHold()
    ticks = int(sim_s * 1000)
    t0 = time.perf_counter()
    for tick in range(ticks):
        state = core.robot_state(tick)
        cmd = law.command(state.stamp_ns)
        core.command(
            as_numpy(cmd.tau_ff),
            as_numpy(cmd.q_des),
            as_numpy(cmd.v_des),
            as_numpy(cmd.kp),
            as_numpy(cmd.kd),
            cmd.stamp_ns,
        )
        core.step()
    return ticks / (time.perf_counter() - t0)


def lockstep_loop(sim_s: float, overrides: Overrides, cameras: bool) -> float:
    """Ticks per wall second of sim + hold over Zenoh."""
    settings = merged(commander("hold", 0.001), overrides)
    return lockstep_rate(["sim", "hold"], settings, sim_s, cameras)


def bench_sim(overrides: Overrides | None = None, sim_s: float = 5.0) -> dict[str, Any]:
    overrides = overrides or {}
    result: dict[str, Any] = {"bench": "sim"}
    for world in ("small", "hall"):
        cost = step_cost(world)
        result[f"{world}_mj_step_us_p50"] = cost["mj_step_us_p50"]
        result[f"{world}_sim_tick_us_p50"] = cost["tick_us_p50"]
    result.update(render_cost())
    bare = [bare_loop(sim_s) for _ in range(3)]
    result["bare_ticks_per_s"] = round(float(np.median(bare)), 1)
    result["lockstep_ticks_per_s"] = round(lockstep_loop(sim_s, overrides, cameras=False), 1)
    result["lockstep_over_bare"] = round(
        result["lockstep_ticks_per_s"] / result["bare_ticks_per_s"], 3
    )
    result["lockstep_with_cameras_ticks_per_s"] = round(
        lockstep_loop(sim_s, overrides, cameras=True), 1
    )
    for key, value in result.items():
        print(f"{key:40s} {value}")
    return result
