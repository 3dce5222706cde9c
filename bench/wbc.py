"""`dume bench wbc`: what a whole-body controller tick costs, and the lockstep rate with it.

- tick p50/p99 (µs) of `WholeBodyController.step` in process, split into model update,
  gait, QP build and OSQP solve, standing and trotting (0.5 m/s) on a MuJoCo floor;
  `build_solve` is what the 0.5 ms target is about; the ratio of the whole tick to the
  bare OSQP solve of the same problems says how much is Python around the solver.
  The set-up's objects are frozen out of the garbage collector first (`gc.freeze`), as
  the service does, so a collection does not walk pinocchio's and MuJoCo's objects.
- lockstep ticks/s of sim + wbc as processes over Zenoh, cameras off, with the controller
  at 1 kHz and at 500 Hz, and at 500 Hz with both cameras (320×240 RGB-D at 10 Hz),
  against the bare in-process loop of `dume bench sim` (PD hold, no transport) measured
  in the same run; ≥ 1000 ticks/s is real time (rtf 1).
"""

from __future__ import annotations

import gc
import os
from typing import Any

import mujoco
import numpy as np

from bench.lockstep import commander, lockstep_rate
from bench.sim import bare_loop
from bench.wbc_harness import floor_spec, set_initial_pose, simulate
from common import robot
from common.config import Overrides, merged
from services.wbc.controller import WbcReferences, WbcState


def tick_times(seconds: float, cmd: tuple[float, float, float]) -> dict[str, np.ndarray]:
    """Per-phase tick times (s) of the controller driving the MuJoCo robot in process."""
    model = floor_spec().compile()
    data = mujoco.MjData(model)
    set_initial_pose(model, data, robot.standing_q())

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        del state
        return WbcReferences(cmd_vel=np.array(cmd) if t > 0.5 else np.zeros(3))

    gc.collect()
    gc.freeze()
    log, _, _ = simulate(model, data, seconds, refs_at)
    gc.unfreeze()
    timing = [t for t in log.timing[100:] if t]  # past the first (cold) ticks
    out = {k: np.array([t[k] for t in timing]) for k in timing[0]}
    out["build_solve"] = out["build"] + out["solve"]
    return out


def _us(x: np.ndarray, q: float) -> float:
    return round(float(np.percentile(x, q)) * 1e6, 1)


def wbc_lockstep_rate(
    period_s: float, sim_s: float, overrides: Overrides, cameras: bool = False
) -> float:
    """Ticks per wall second of sim + wbc in lockstep (the controller standing)."""
    settings = merged(commander("wbc", period_s), overrides)
    return lockstep_rate(["sim", "wbc"], settings, sim_s, cameras)


def bench_wbc(overrides: Overrides | None = None, sim_s: float = 5.0) -> dict[str, Any]:
    overrides = overrides or {}
    result: dict[str, Any] = {"bench": "wbc"}
    for name, cmd in (("stand", (0.0, 0.0, 0.0)), ("trot", (0.5, 0.0, 0.0))):
        t = tick_times(3.0, cmd)
        for phase in ("total", "build_solve", "solve", "model", "build"):
            result[f"{name}_{phase}_p50_us"] = _us(t[phase], 50)
            result[f"{name}_{phase}_p99_us"] = _us(t[phase], 99)
        result[f"{name}_tick_over_solve_p50"] = round(
            float(np.median(t["total"]) / np.median(t["solve"])), 2
        )
    result["bare_ticks_per_s"] = round(float(np.median([bare_loop(sim_s) for _ in range(3)])), 1)
    for name, period, cameras in (
        ("1000hz", 0.001, False),
        ("500hz", 0.002, False),
        ("500hz_cameras", 0.002, True),
    ):
        rate = wbc_lockstep_rate(period, sim_s, overrides, cameras)
        result[f"lockstep_wbc_{name}_ticks_per_s"] = round(rate, 1)
        result[f"lockstep_wbc_{name}_rtf"] = round(rate / 1000.0, 3)
        result[f"lockstep_wbc_{name}_over_bare"] = round(rate / result["bare_ticks_per_s"], 3)
    result["load_average_1min"] = round(os.getloadavg()[0], 2)  # a shared machine: context
    for key, value in result.items():
        print(f"{key:40s} {value}")
    return result
