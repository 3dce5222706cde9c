"""`dume trial walk|turn|strafe|random|reach|pick|push`: the controller's acceptance trials.

Each runs over a real stack (router + sim + wbc as processes, lockstep, dynamic
locomotion; see `bench.trial_driver`) and returns JSON-ready figures; the CLI prints them
on its last line. The robot is steered by its own odometry; what it did is measured on
the sim's truth, and every trial reports the odometry's errors against it (`odometry`).

- walk: 5 m at 0.5 m/s; final error to the point 5 m ahead, lateral drift.
- strafe: 2 m to the left at 0.3 m/s; final error, forward drift.
- turn: 360° in place at 0.5 rad/s; yaw turned, how far the base wandered.
- random: 120 s of random velocity commands within the limits, changed every 2 s, inside
  a disc of free floor near the start (back towards its centre whenever out of it);
  never falls, never touches anything (`bench.trial_random`).
- reach: in manipulate, 20 `gripper_tcp` goals in the base frame, each the forward
  kinematics of a random collision-free arm configuration near `ready`; every goal's
  outcome and time.
- pick: the truth pose of the small world's bottle → walk to the stance across the table
  edge (round the table when it is in the way) → ready → Reach with a pre-grasp approach
  → Grasp → lift 10 cm → stow → walk 20 s at 0.3 m/s holding it (`bench.trial_pick`).
- localize, localize-off: the localizer on the robot's scans and odometry during the
  random walk, people walking by; told the start pose exactly, or 0.5 m and 10° off
  (`bench.trial_localize`).
- push: 20 N·s lateral pushes on the base (200 N for 0.1 s, `dume/world/push`): standing,
  then trotting at 0.5 m/s, to the left and to the right; after each, the lowest base,
  the largest roll/pitch and how far the base was thrown sideways; never falls.

Navigation's trials run over the full navigation stack instead (`bench.nav_run`):
- goto X Y [yaw]: one pose goal (`bench.trial_goto`).
- goals: `count` random goals in a row across the world (`bench.trial_goals`).
- person: a person steps into the path (hall, seed 3; `bench.nav_person`); crossing: a
  person walks across it without stopping; both judged by the speed and separation
  monitor's rule from truth.

- fetch: one bring-me by the real mission over the full stack, its manipulation measured
  against the sim's truth (approach error, where the jaws closed, pull felt against taken;
  `bench.trial_fetch`).
- patrol: the mission's mapping patrol from an empty map with the floor plan
  (`bench.trial_patrol`); explore: its exploration from nothing, no floor plan, the small
  world by default (`bench.trial_explore`): goals, time, known floor, the occupancy's
  agreement with the truth.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from typing import Any

import numpy as np
import pinocchio as pin

from bench.trial_driver import Driver, Script, start_stack
from bench.trial_localize import localize
from bench.trial_pick import pick
from bench.trial_random import random_walk
from common import robot
from common.config import REPO_ROOT, Overrides, merged
from common.geometry import rpy_of_quat_xyzw, wrap_angle
from common.messages.wbc import Posture, Reach

NAV_TRIALS = ("goto", "goals", "person", "crossing")
Figures = dict[str, Any]


def _mat4(T: np.ndarray) -> tuple[float, ...]:
    return tuple(float(x) for x in np.asarray(T).ravel())


def _travel(d: Driver, v: tuple[float, float, float], seconds: float) -> Script:
    d.mode("walk")
    yield from d.wait(0.5)
    d.cmd(*v)
    yield from d.wait(seconds)
    d.cmd(0.0)
    yield from d.wait(2.0)


def straight(d: Driver, v: tuple[float, float, float], seconds: float, out: Figures) -> Script:
    p0, yaw0 = d.base(truth=True)
    yield from _travel(d, v, seconds)
    p1, _ = d.base(truth=True)
    c, s = math.cos(yaw0), math.sin(yaw0)
    goal_b = np.array(v[:2]) * seconds
    goal = p0 + np.array([c * goal_b[0] - s * goal_b[1], s * goal_b[0] + c * goal_b[1]])
    along = goal - p0
    along /= np.linalg.norm(along)
    moved = p1 - p0
    out["distance_m"] = round(float(moved @ along), 3)
    out["final_error_m"] = round(float(np.linalg.norm(p1 - goal)), 3)
    out["drift_m"] = round(float(abs(moved @ np.array([-along[1], along[0]]))), 3)


def walk(d: Driver, out: Figures) -> Script:
    yield from straight(d, (0.5, 0.0, 0.0), 10.0, out)
    out["lateral_drift_m"] = out.pop("drift_m")


def strafe(d: Driver, out: Figures) -> Script:
    yield from straight(d, (0.0, 0.3, 0.0), 2.0 / 0.3, out)
    out["forward_drift_m"] = out.pop("drift_m")


def turn(d: Driver, out: Figures) -> Script:
    p0, yaw = d.base(truth=True)
    turned, last = 0.0, yaw
    d.mode("walk")
    yield from d.wait(0.5)
    d.cmd(0.0, 0.0, 0.5)
    end = d.t + 2 * math.pi / 0.5
    while d.t < end + 2.0:
        if d.t >= end:
            d.cmd(0.0)
        _, yaw = d.base(truth=True)
        turned += wrap_angle(yaw - last)
        last = yaw
        yield
    out["yaw_turned_deg"] = round(math.degrees(turned), 1)
    out["position_drift_m"] = round(float(np.linalg.norm(d.base(truth=True)[0] - p0)), 3)


def _after_push(d: Driver, seconds: float, lateral: np.ndarray) -> Generator[None, None, Figures]:
    """Watch the base for `seconds`: lowest height, largest tilt, largest sideways excursion."""
    p0, _ = d.base(truth=True)
    low, tilt, side = math.inf, 0.0, 0.0
    end = d.t + seconds
    while d.t < end and not d.fell:
        assert d.truth is not None
        low = min(low, d.truth.base_position_in_world[2])
        roll_pitch = rpy_of_quat_xyzw(d.truth.base_orientation_xyzw)[:2]
        tilt = max(tilt, float(np.degrees(np.max(np.abs(roll_pitch)))))
        side = max(side, abs(float((d.base(truth=True)[0] - p0) @ lateral)))
        yield
    return {
        "min_base_height_m": round(low, 4),
        "max_roll_pitch_deg": round(tilt, 2),
        "max_sideways_m": round(side, 3),
        "fell": d.fell,
    }


def push(d: Driver, out: Figures, impulse_ns: float = 20.0, duration_s: float = 0.1) -> Script:
    """Lateral pushes of `impulse_ns` standing, then trotting at 0.5 m/s (left, right)."""
    force = impulse_ns / duration_s
    d.mode("walk")
    yield from d.wait(1.0)
    pushes = (("stand_left", 0.0, 1.0), ("trot_left", 0.5, 1.0), ("trot_right", 0.5, -1.0))
    for name, vx, side in pushes:
        if vx and d.velocity[0] != vx:
            d.cmd(vx)
            yield from d.wait(3.0)  # steady trot first
        _, yaw = d.base()
        lateral = np.array([-math.sin(yaw), math.cos(yaw)])  # base_yaw's +y in world
        f = side * force * lateral
        d.push((f[0], f[1], 0.0), duration_s)
        out[name] = yield from _after_push(d, 3.0, side * lateral)
        if d.fell:
            break
    d.cmd(0.0)
    yield from d.wait(2.0)
    out["impulse_ns"] = impulse_ns
    out["survived"] = (
        not d.fell
        and all(
            out[n]["min_base_height_m"] > 0.3 and out[n]["max_roll_pitch_deg"] < 30.0
            for n, _, _ in pushes
            if n in out
        )
        and all(n in out for n, _, _ in pushes)
    )


def random_arm_targets(n: int, seed: int) -> list[np.ndarray]:
    """TCP poses in the base frame from random collision-free arm configurations."""
    model, geom = robot.load_pinocchio()
    data, gdata = model.createData(), geom.createData()
    rng = np.random.default_rng(seed)
    frame = model.getFrameId(robot.TCP_FRAME)
    ready = robot.POSTURES["ready"]
    out: list[np.ndarray] = []
    while len(out) < n:
        joints = ready.copy()
        joints[12:18] += rng.uniform(-0.5, 0.5, 6)
        joints = np.clip(joints, robot.POSITION_LOWER + 0.1, robot.POSITION_UPPER - 0.1)
        q = np.concatenate([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], joints])
        pin.framesForwardKinematics(model, data, q)
        H = data.oMf[frame].homogeneous.copy()
        in_front = H[0, 3] > 0.35 and H[2, 3] > -0.1
        if in_front and not pin.computeCollisions(model, data, geom, gdata, q, True):
            out.append(H)
    return out


def reach(d: Driver, out: Figures, n: int = 20, seed: int = 0) -> Script:
    d.mode("manipulate")
    yield from d.wait(0.5)
    yield from d.finish(d.goal(Posture(name="ready")), 5.0)
    times, errors, outcomes = [], [], []
    for H in random_arm_targets(n, seed):
        t0 = d.t
        goal = Reach(H=_mat4(H), frame="base", stamp_ns=d.t_ns, pregrasp_m=0.0)
        g = yield from d.finish(d.goal(goal), 6.0)
        outcomes.append("timeout" if g is None else g.state)
        times.append(d.t - t0)
        assert d.status is not None
        errors.append((d.status.gripper_error_m, math.degrees(d.status.gripper_error_rad)))
    ok = [o == "succeeded" for o in outcomes]
    out |= {
        "targets": n,
        "succeeded": sum(ok),
        "within_3s": sum(o and t <= 3.0 for o, t in zip(ok, times, strict=True)),
        "max_time_s": round(max(times), 2),
        "max_error_m": round(max(e[0] for e in errors), 4),
        "max_error_deg": round(max(e[1] for e in errors), 2),
    }


#: The start pose the localizer is given in `localize-off`: 0.5 m and 10° off.
LOCALIZE_OFF = (0.4, -0.3, math.radians(10.0))


SCRIPTS = {
    "walk": walk,
    "turn": turn,
    "strafe": strafe,
    "random": random_walk,
    "reach": reach,
    "pick": pick,
    "push": push,
    "localize": lambda d, out: localize(d, out),
    "localize-off": lambda d, out: localize(d, out, start_off=LOCALIZE_OFF),
    "slam": lambda d, out: localize(d, out, slam=True),
}
#: The trials whose robot is on its own odometry, with people walking by.
OWN_ODOMETRY = {"localize", "localize-off", "slam"}


#: Where each trial runs by default: the hall's seed 3 has 6 m free ahead of the start
#: and 3 m to its left; the small world has a bottle on a table in front of the robot.
WORLDS = {
    "walk": ("hall", 3),
    "strafe": ("hall", 3),
    "turn": ("hall", 3),
    "random": ("hall", 3),
    "push": ("hall", 3),
    "localize": ("hall", 3),
    "localize-off": ("hall", 3),
    "slam": ("hall", 3),
    "goto": ("hall", 3),
    "goals": ("hall", 3),
}
DEFAULT_WORLD = ("small", 1)


def run_trial(
    name: str,
    world_seed: int | None = None,
    wbc_period_s: float = 0.002,
    overrides: Overrides | None = None,
    options: dict[str, Any] | None = None,
) -> Figures:
    """Run one trial on a fresh stack; its figures. `options`: the navigation trials'
    `world`, and goto's `x`, `y`, `yaw` or goals' `count`."""
    world, seed = WORLDS.get(name, DEFAULT_WORLD)
    seed = seed if world_seed is None else world_seed
    if name in NAV_TRIALS:
        return _nav_trial(name, seed, overrides or {}, dict(options or {}), world)
    if name == "patrol":  # the mission's mapping patrol from an empty map
        from bench.trial_patrol import patrol_run

        world = (options or {}).get("world") or "hall"
        return patrol_run(world, 0 if world_seed is None else world_seed, overrides)
    if name == "explore":  # the mission's exploration from nothing, no floor plan
        from bench.trial_explore import explore_run

        world = (options or {}).get("world") or "small"
        return explore_run(world, 0 if world_seed is None else world_seed, overrides)
    if name == "faults":  # each service killed or hung in each phase of a fetch
        from bench.trial_faults import PHASES, SIGNALS, TARGETS, run_faults

        opts = dict(options or {})
        return run_faults(
            opts.get("services") or TARGETS,
            opts.get("phases") or tuple(PHASES),
            opts.get("signals") or tuple(SIGNALS),
            opts.get("count") or 5,
            overrides or {},
        )
    if name == "soak":  # requests for `minutes` on one stack: memory and files per service
        from bench.trial_soak import run_soak

        return run_soak(float((options or {}).get("minutes") or 120.0), overrides or {})
    if name == "updown":  # dume up, dume down, again and again: nothing left behind
        from bench.trial_updown import run_updown

        return run_updown((options or {}).get("count") or 100, overrides)
    if name == "fuzz":  # every key every service takes, fuzzed; no service may crash
        from bench.trial_fuzz import run_fuzz

        return run_fuzz((options or {}).get("count") or 10_000, world_seed or 0, overrides)
    if name == "fetch":  # the real mission over the full stack, with truth probes
        from bench.trial_fetch import run_fetch

        opts = options or {}
        world = opts.get("world") or "small"
        samples = REPO_ROOT / "var" / "trials" / f"fetch-{world}-{seed}.handover.json"
        samples.parent.mkdir(parents=True, exist_ok=True)
        asked = (str(opts.get("object") or ""), str(opts.get("person") or ""))
        return run_fetch(seed, overrides, samples, world_name=world, asked=asked) | {
            "handover_samples": str(samples.relative_to(REPO_ROOT))
        }
    out: Figures = {"trial": name, "world": world, "world_seed": seed}
    out["wbc_period_s"] = wbc_period_s
    if name in OWN_ODOMETRY:
        own = {"wbc.base_state": "estimate", "sim.walking_people": True}
        overrides = merged(own, overrides or {})
    with start_stack(world, seed, wbc_period_s, overrides) as stack:
        d = Driver(stack)
        d.start()
        figures: Figures = {}
        d.run(SCRIPTS[name](d, figures))
    return out | d.figures() | figures


def _nav_trial(
    name: str, seed: int, overrides: Overrides, opts: dict[str, Any], world: str
) -> Figures:
    world = opts.pop("world", None) or world
    if name == "goto":
        from bench.trial_goto import goto

        return goto(opts["x"], opts["y"], opts.get("yaw", 0.0), world, seed, overrides)
    if name in ("person", "crossing"):
        from bench.nav_person import person_trial

        return person_trial(overrides, "step_in" if name == "person" else name)
    from bench.trial_goals import goals_trial

    return goals_trial(opts.get("count") or 10, world, seed, overrides)
