"""`dume trial walk|turn|strafe|random|reach|pick|push`: the controller's acceptance trials.

Each runs over a real stack (router + sim + wbc as processes, lockstep, dynamic
locomotion; see `bench.trial_driver`) and returns JSON-ready figures; the CLI prints them
on its last line.

- walk: 5 m at 0.5 m/s; final error to the point 5 m ahead, lateral drift.
- strafe: 2 m to the left at 0.3 m/s; final error, forward drift.
- turn: 360° in place at 0.5 rad/s; yaw turned, how far the base wandered.
- random: 120 s of random velocity commands within the limits, changed every 2 s (and
  back towards the middle of a free area when 1.2 m out); never falls.
- reach: in manipulate, 20 `gripper_tcp` goals in the base frame, each the forward
  kinematics of a random collision-free arm configuration near `ready`; every goal's
  outcome and time.
- pick: the truth pose of the small world's bottle (`dume/world/description`, truth:
  perception comes later) → walk to the stance across the table edge → ready → Reach
  with a pre-grasp approach → Grasp → lift 10 cm → stow → turn away from the table →
  walk 20 s at 0.3 m/s on a 1 m circle (clear of the table); held by the grasp detector
  and never dropped (the sim's drop events).
- push: needs a push hook in the sim, which it does not have yet: says so.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from bench.spike_wbc import grasp_plan
from bench.trial_driver import Driver, Script, start_stack
from common import robot
from common.geometry import wrap_angle
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS
from common.messages.sim import ObjectDropped, WorldEvents
from common.messages.wbc import Grasp, Posture, Reach
from common.messages.world import WorldDescription

TRIALS = ("walk", "turn", "strafe", "random", "reach", "pick", "push")
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
    p0, yaw0 = d.base()
    yield from _travel(d, v, seconds)
    p1, _ = d.base()
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
    p0, yaw = d.base()
    turned, last = 0.0, yaw
    d.mode("walk")
    yield from d.wait(0.5)
    d.cmd(0.0, 0.0, 0.5)
    end = d.t + 2 * math.pi / 0.5
    while d.t < end + 2.0:
        if d.t >= end:
            d.cmd(0.0)
        _, yaw = d.base()
        turned += wrap_angle(yaw - last)
        last = yaw
        yield
    out["yaw_turned_deg"] = round(math.degrees(turned), 1)
    out["position_drift_m"] = round(float(np.linalg.norm(d.base()[0] - p0)), 3)


def random_walk(d: Driver, out: Figures, seconds: float = 120.0, seed: int = 0) -> Script:
    """Random (vx, vy, wz) within the limits every 2 s, heading back when 1.2 m out."""
    rng = np.random.default_rng(seed)
    p0, yaw0 = d.base()
    centre = p0 + 2.0 * np.array([math.cos(yaw0), math.sin(yaw0)])  # 6 m free ahead
    d.mode("walk")
    yield from d.wait(0.5)
    end, segments, returns = d.t + seconds, 0, 0
    while d.t < end:
        p, yaw = d.base()
        e = centre - p
        if np.linalg.norm(e) > 1.2:
            c, s = math.cos(yaw), math.sin(yaw)
            back = 0.5 * np.array([c * e[0] + s * e[1], -s * e[0] + c * e[1]]) / np.linalg.norm(e)
            d.cmd(float(back[0]), float(back[1]), 0.0)
            returns += 1
        else:
            d.cmd(*(float(x) for x in rng.uniform(-1.0, 1.0, 3) * [0.8, 0.4, 1.0]))
            segments += 1
        yield from d.wait(2.0)
    d.cmd(0.0)
    yield from d.wait(2.0)
    out |= {"random_segments": segments, "return_segments": returns}


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


def _go_to(d: Driver, xy: np.ndarray, yaw: float, timeout_s: float) -> Script:
    """Trot to (x, y, yaw) on proportional commands (no planner: a free straight line)."""
    d.mode("walk")
    end = d.t + timeout_s
    while d.t < end:
        p, now = d.base()
        e, e_yaw = xy - p, wrap_angle(yaw - now)
        if np.linalg.norm(e) < 0.03 and abs(e_yaw) < 0.03:
            break
        c, s = math.cos(now), math.sin(now)
        ex, ey = c * e[0] + s * e[1], -s * e[0] + c * e[1]
        d.cmd(
            float(np.clip(1.0 * ex, -0.4, 0.4)),
            float(np.clip(1.0 * ey, -0.2, 0.2)),
            float(np.clip(1.5 * e_yaw, -0.5, 0.5)),
        )
        yield
    d.cmd(0.0)
    yield from d.wait(1.0)


def pick(d: Driver, out: Figures, walk_s: float = 20.0) -> Script:
    world = d.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
    plan = grasp_plan(world)  # truth: the bottle's pose from the sim's world description
    events = d.bus.fifo(WORLD_EVENTS, WorldEvents)
    q0 = plan.q0
    yield from _go_to(d, q0[:2], 2 * math.atan2(q0[5], q0[6]), 30.0)
    p, _ = d.base()
    out["stance_error_m"] = round(float(np.linalg.norm(p - q0[:2])), 3)
    d.mode("manipulate")
    yield from d.wait(0.5)
    steps: list[tuple[str, Any, float]] = [
        ("ready", Posture(name="ready"), 5.0),
        ("reach", Reach(H=_mat4(plan.T_grasp), frame="world", stamp_ns=0,
                        pregrasp_m=0.12), 8.0),
        ("grasp", Grasp(max_effort=4.0), 4.0),
    ]  # fmt: skip
    T_lift = plan.T_grasp.copy()
    T_lift[2, 3] += 0.10
    steps += [
        ("lift", Reach(H=_mat4(T_lift), frame="world", stamp_ns=0, pregrasp_m=0.0), 5.0),
        ("stow", Posture(name="stow"), 5.0),
    ]
    for name, goal, timeout in steps:
        g = yield from d.finish(d.goal(goal), timeout)
        out[name] = "timeout" if g is None else g.state
        if g is None or g.state != "succeeded":
            out["failed_at"] = name if g is None else f"{name}: {g.reason}"
            break
    else:
        d.mode("walk")
        yield from d.wait(0.5)
        d.cmd(0.0, 0.0, -0.5)  # turn away from the table, then circle clear of it
        yield from d.wait(math.pi / 0.5)
        p0, _ = d.base()
        d.cmd(0.3, 0.0, -0.3)
        yield from d.wait(walk_s)
        d.cmd(0.0)
        yield from d.wait(1.5)
        out["walked_s"], out["end_from_walk_start_m"] = (
            walk_s,
            round(float(np.linalg.norm(d.base()[0] - p0)), 3),
        )
    dropped = [e for w in events.drain() for e in w.events if isinstance(e, ObjectDropped)]
    assert d.status is not None
    out["held"] = bool(d.status.held and not dropped and "failed_at" not in out)
    out["dropped"] = len(dropped)
    out["gripper_angle_rad"] = round(d.status.gripper_angle, 3)
    out["gripper_wrench_base"] = [round(x, 2) for x in d.status.gripper_wrench]


SCRIPTS = {
    "walk": walk,
    "turn": turn,
    "strafe": strafe,
    "random": random_walk,
    "reach": reach,
    "pick": pick,
}


#: Where each trial runs by default: the hall's seed 3 has 6 m free ahead of the start
#: and 3 m to its left; the small world has a bottle on a table in front of the robot.
WORLDS = {"walk": ("hall", 3), "strafe": ("hall", 3), "turn": ("hall", 3), "random": ("hall", 3)}
DEFAULT_WORLD = ("small", 1)


def run_trial(
    name: str,
    world_seed: int | None = None,
    wbc_period_s: float = 0.002,
    overrides: list[str] | None = None,
) -> Figures:
    """Run one trial on a fresh stack; its figures."""
    world, seed = WORLDS.get(name, DEFAULT_WORLD)
    seed = seed if world_seed is None else world_seed
    out: Figures = {"trial": name, "world": world, "world_seed": seed}
    out["wbc_period_s"] = wbc_period_s
    if name == "push":
        out["skipped"] = "the sim has no push hook (an external impulse on the base) yet"
        return out
    with start_stack(world, seed, wbc_period_s, overrides or []) as stack:
        d = Driver(stack)
        d.start()
        figures: Figures = {}
        d.run(SCRIPTS[name](d, figures))
    return out | d.figures() | figures
