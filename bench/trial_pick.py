"""The `pick` trial: walk to the table, pick the bottle by its truth pose, stow, walk with it.

The truth pose of the world's bottle (`dume/world/description`, truth: perception comes
later) gives the stance across the nearest table edge (`bench.wbc_harness.grasp_plan`). The
robot walks there on proportional commands; when the straight line crosses the table
(the stance is on its far side, e.g. the small world's seed 0), it goes round it: via
the corners of the table's footprint grown by `CLEARANCE_M`, the shortest way that
does not cross it (`route_around`), to a point `PRE_STANCE_M` back from the stance,
then straight in. At the stance: ready → Reach with a pre-grasp approach → Grasp → lift
10 cm → stow; then it walks `walk_s` at 0.3 m/s still holding it: back along its route
(so away from the table and the walls), then on a 1 m circle. Held by the grasp
detector and never dropped (the sim's drop events).
"""

from __future__ import annotations

import heapq
import math
from typing import Any

import numpy as np

from bench.trial_driver import Driver, Script
from bench.wbc_harness import grasp_plan
from common.geometry import FloatArray, wrap_angle, yaw_of_quat_xyzw
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS
from common.messages.sim import ObjectDropped, WorldEvents
from common.messages.wbc import Grasp, Posture, Reach
from common.messages.world import Obstacle, WorldDescription

Figures = dict[str, Any]
CLEARANCE_M = 0.75  # the base's centre from the table's edge when going round it
PRE_STANCE_M = 0.5  # back from the stance along the approach, where the straight-in starts
WALK_SPEED = 0.3  # m/s, with the bottle


def _mat4(T: FloatArray) -> tuple[float, ...]:
    return tuple(float(x) for x in np.asarray(T).ravel())


def crosses_box(a: FloatArray, b: FloatArray, box: Obstacle, grow: float) -> bool:
    """Whether the segment a→b (2,) crosses the box's footprint grown by `grow` (m)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    centre = np.array(box.centre[:2])
    R = np.array([[c, -s], [s, c]])
    pa, pb = R.T @ (np.asarray(a) - centre), R.T @ (np.asarray(b) - centre)
    d = pb - pa
    t0, t1 = 0.0, 1.0
    for i in range(2):
        half = box.half_size[i] + grow
        if abs(d[i]) < 1e-12:
            if abs(pa[i]) > half:
                return False
            continue
        ta, tb = (-half - pa[i]) / d[i], (half - pa[i]) / d[i]
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if t0 > t1:
            return False
    return True


def route_around(
    start: FloatArray, goal: FloatArray, box: Obstacle, clearance: float
) -> list[FloatArray]:
    """Waypoints (the goal last) from start to goal that keep `clearance` from the box:
    the goal alone when the straight line is clear, else the shortest way via the corners
    of the grown footprint (each leg checked against a slightly smaller footprint, so the
    legs along its edges count as clear). The goal alone too when no way is found."""
    test = clearance - 0.02
    if not crosses_box(start, goal, box, test):
        return [np.asarray(goal, float)]
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    R = np.array([[c, -s], [s, c]])
    hx, hy = box.half_size[0] + clearance, box.half_size[1] + clearance
    corners = [np.array(box.centre[:2]) + R @ np.array([sx * hx, sy * hy])
               for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]  # fmt: skip
    nodes = [np.asarray(start, float), np.asarray(goal, float), *corners]
    best = {0: 0.0}
    previous: dict[int, int] = {}
    queue = [(0.0, 0)]
    while queue:
        cost, i = heapq.heappop(queue)
        if i == 1:
            break
        if cost > best.get(i, math.inf):
            continue
        for j in range(1, len(nodes)):
            if j == i or crosses_box(nodes[i], nodes[j], box, test):
                continue
            new = cost + float(np.linalg.norm(nodes[j] - nodes[i]))
            if new < best.get(j, math.inf):
                best[j], previous[j] = new, i
                heapq.heappush(queue, (new, j))
    if 1 not in previous:
        return [nodes[1]]
    path, i = [], 1
    while i != 0:
        path.append(nodes[i])
        i = previous[i]
    return path[::-1]


def go_to(
    d: Driver,
    xy: FloatArray,
    yaw: float | None,
    timeout_s: float,
    tol_m: float = 0.03,
    v_max: float = 0.4,
    stop: bool = True,
) -> Script:
    """Trot to (x, y) on proportional commands along a free straight line; with `yaw`, end
    facing it, without, face the way there (slower while the heading is off)."""
    d.mode("walk")
    end = d.t + timeout_s
    while d.t < end:
        p, now = d.base()
        e = xy - p
        dist = float(np.linalg.norm(e))
        heading = math.atan2(e[1], e[0]) if yaw is None else yaw
        e_yaw = wrap_angle(heading - now)
        if dist < tol_m and (yaw is None or abs(e_yaw) < 0.03):
            break
        c, s = math.cos(now), math.sin(now)
        ex, ey = c * e[0] + s * e[1], -s * e[0] + c * e[1]
        if yaw is None:  # walk forwards: only as fast as the heading allows
            ex *= max(0.0, math.cos(e_yaw)) ** 2
        d.cmd(
            float(np.clip(1.0 * ex, -v_max, v_max)),
            float(np.clip(1.0 * ey, -0.2, 0.2)),
            float(np.clip(1.5 * e_yaw, -0.5, 0.5)),
        )
        yield
    if stop:
        d.cmd(0.0)
        yield from d.wait(1.0)


def walk_holding(d: Driver, seconds: float, waypoints: list[FloatArray]) -> Script:
    """Walk for `seconds` at WALK_SPEED: through `waypoints`, then on a 1 m circle."""
    end = d.t + seconds
    for wp in waypoints:
        yield from go_to(d, wp, None, end - d.t, tol_m=0.15, v_max=WALK_SPEED, stop=False)
    d.cmd(WALK_SPEED, 0.0, -WALK_SPEED)
    while d.t < end:
        yield
    d.cmd(0.0)


def pick(d: Driver, out: Figures, walk_s: float = 20.0) -> Script:
    world = d.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
    plan = grasp_plan(world)  # truth: the bottle's pose from the sim's world description
    table = next(o for o in world.obstacles if o.id == world.artifacts[0].surface_id)
    events = d.bus.fifo(WORLD_EVENTS, WorldEvents)
    q0 = plan.q0
    start, _ = d.base()
    pre = q0[:2] - PRE_STANCE_M * plan.approach
    route = [*route_around(start, pre, table, CLEARANCE_M), q0[:2]]  # then straight in
    out["route"] = [[round(float(x), 2) for x in wp] for wp in route]
    for wp in route[:-1]:
        yield from go_to(d, wp, None, 30.0, tol_m=0.1, stop=False)
    yield from go_to(d, q0[:2], yaw_of_quat_xyzw(q0[3:7]), 30.0)
    p, _ = d.base()
    out["stance_error_m"] = round(float(np.linalg.norm(p - q0[:2])), 3)
    d.mode("manipulate")
    yield from d.wait(0.5)
    T_lift = plan.T_grasp.copy()
    T_lift[2, 3] += 0.10
    steps: list[tuple[str, Any, float]] = [
        ("ready", Posture(name="ready"), 5.0),
        ("reach", Reach(H=_mat4(plan.T_grasp), frame="world", stamp_ns=0, pregrasp_m=0.12), 8.0),
        ("grasp", Grasp(max_effort=4.0), 4.0),
        ("lift", Reach(H=_mat4(T_lift), frame="world", stamp_ns=0, pregrasp_m=0.0), 5.0),
        ("stow", Posture(name="stow"), 5.0),
    ]
    for name, goal, timeout in steps:
        g = yield from d.finish(d.goal(goal), timeout)
        out[name] = "timeout" if g is None else g.state
        if g is None or g.state != "succeeded":
            out["failed_at"] = name if g is None else f"{name}: {g.reason}"
            break
        if name == "lift":  # how far the held bottle sags the gripper, once settled
            yield from d.wait(1.0)
            assert d.status is not None
            out["lift_error_m"] = round(d.status.gripper_error_m, 4)
            out["lift_wrench_base"] = [round(x, 2) for x in d.status.gripper_wrench]
    else:
        p0, _ = d.base(truth=True)
        back = [*route[-2::-1], start]  # the way it came: clear of the table and walls
        yield from walk_holding(d, walk_s, back)
        yield from d.wait(1.5)
        out["walked_s"] = walk_s
        out["end_from_walk_start_m"] = round(float(np.linalg.norm(d.base(truth=True)[0] - p0)), 3)
    dropped = [e for w in events.drain() for e in w.events if isinstance(e, ObjectDropped)]
    assert d.status is not None
    out["held"] = bool(d.status.held and not dropped and "failed_at" not in out)
    out["dropped"] = len(dropped)
    out["gripper_angle_rad"] = round(d.status.gripper_angle, 3)
    out["gripper_wrench_base"] = [round(x, 2) for x in d.status.gripper_wrench]
