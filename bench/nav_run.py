"""Navigation over a real stack, measured from the sim's truth: the trials' shared part.

`nav_stack` starts router + sim + wbc + semantic_map + navigation as processes, lockstep,
dynamic locomotion, the head camera on (navigation's short-lived layer), the semantic map
seeded from the world into a fresh database, navigation on `map_source="map"` (so the map's
occupancy and people queryables are exercised), the WBC walking on navigation's cmd_vel.
`NavRun` sends goals and watches every 50 Hz sample of the base's truth (`state_truth`:
the robot's own `odom` drifts when it estimates its base) and the world's contact events
(truth, evaluation only): path length walked, closest approach of the footprint (arm
stowed) to the static obstacles (oriented boxes, exact rectangle-to-rectangle distance)
and to the people (their floor points at t = 0: people stand unless
`sim.walking_people`), and contacts, per goal. Over the whole run, the robot's own
estimates against the truth: its odometry (`EstimateErrors`: drift over the distance
walked) and its localization (`LocalizationErrors`), none in the truth ablation.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bench.estimate_errors import Estimates
from common.clients import NavClient, Refused
from common.config import Overrides, merged
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS
from common.messages.localization import Localization
from common.messages.navigation import NavGoal, NavGoalReply, NavStatus, PoseGoal
from common.messages.sim import Odom, RobotContact, StateTruth, WorldEvents
from common.messages.world import WorldDescription
from common.robot import Footprint
from deploy.stack import ProcessStack
from services.navigation.grid import Pose

Corners = NDArray[np.float64]  # (4, 2) m, world, counter-clockwise


def rectangle(
    x: float, y: float, yaw: float, ahead: float, behind: float, half_w: float
) -> Corners:
    """The corners of a rectangle about (x, y) turned by yaw: `ahead`/`behind` along its x."""
    local = np.array([[ahead, -half_w], [ahead, half_w], [-behind, half_w], [-behind, -half_w]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def footprint_corners(x: float, y: float, yaw: float, fp: Footprint) -> Corners:
    return rectangle(x, y, yaw, fp.front, fp.back, fp.half_width)


def _separated(a: Corners, b: Corners) -> bool:
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for n in np.stack([edges[:, 1], -edges[:, 0]], axis=1):
            pa, pb = a @ n, b @ n
            if pa.max() < pb.min() or pb.max() < pa.min():
                return True
    return False


def _point_segments(p: NDArray[np.float64], poly: Corners) -> float:
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(((p - a) * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + t[:, None] * ab - p).T)))


def rect_distance(a: Corners, b: Corners) -> float:
    """The distance between two convex polygons, m (0 when they overlap)."""
    if not _separated(a, b):
        return 0.0
    return min(
        min(_point_segments(p, b) for p in a),
        min(_point_segments(p, a) for p in b),
    )


def obstacle_boxes(world: WorldDescription) -> list[tuple[str, Corners]]:
    return [
        (
            o.id,
            rectangle(
                o.centre[0], o.centre[1], o.yaw, o.half_size[0], o.half_size[0], o.half_size[1]
            ),
        )
        for o in world.obstacles
    ]


def nav_settings(world: str, seed: int, db_dir: str) -> dict[str, Any]:
    return {
        "sim.world": world,
        "sim.world_seed": seed,
        "sim.locomotion": "dynamic",
        "sim.cameras": ["camera_head"],
        "time.mode": "lockstep",
        "semantic_map.start": "seed-from-world",
        "semantic_map.reset": True,
        "semantic_map.dir": db_dir,
        "semantic_map.name": "trial",
        "navigation.map_source": "map",
        "wbc.initial_mode": "walk",
        "recording.enabled": False,
    }


def nav_stack(
    world: str, seed: int, extra: Overrides | None = None, perception: bool = False
) -> ProcessStack:
    db = tempfile.mkdtemp(prefix="dume-nav-trial-")
    services = ["sim", "wbc", "semantic_map", "navigation", "localization"]
    if perception:
        services.insert(2, "perception")
    return ProcessStack(services, merged(nav_settings(world, seed, db), extra or {}))


def send_goal(stack: ProcessStack, goal: NavGoal) -> NavGoalReply:
    """The goal's id, or the refusal's reason, as a reply (sent once: navigation takes a
    goal sent before its map and resolves it when the map comes)."""
    try:
        goal_id = NavClient(stack.bus, stack.keys, 30.0).send(goal)
        return NavGoalReply(accepted=True, goal_id=goal_id)
    except Refused as exc:
        return NavGoalReply(accepted=False, reason=str(exc))


@dataclass
class GoalFigures:
    """What one goal did (sim truth)."""

    goal: tuple[float, float, float]
    state: str = "refused"
    reason: str = ""
    sim_s: float = 0.0
    wall_s: float = 0.0
    path_m: float = 0.0
    final_error_m: float = math.nan
    final_yaw_error_rad: float = math.nan
    closest_obstacle_m: float = math.inf
    closest_obstacle: str = ""
    closest_person_m: float = math.inf
    contacts: dict[str, int] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        def r(v: float, n: int = 3) -> float | None:
            return round(v, n) if math.isfinite(v) else None

        return {
            "goal": [round(v, 3) for v in self.goal],
            "reached": self.state == "succeeded",
            "state": self.state,
            "reason": self.reason,
            "sim_s": r(self.sim_s, 2),
            "wall_s": r(self.wall_s, 1),
            "path_m": r(self.path_m, 2),
            "final_error_m": r(self.final_error_m),
            "final_yaw_error_rad": r(self.final_yaw_error_rad),
            "closest_obstacle_m": r(self.closest_obstacle_m),
            "closest_obstacle": self.closest_obstacle,
            "closest_person_m": r(self.closest_person_m),
            "contacts": dict(sorted(self.contacts.items())),
        }


class NavRun:
    """Goals sent to a running navigation stack, watched from the truth side."""

    def __init__(self, stack: ProcessStack) -> None:
        self.stack = stack
        bus, keys = stack.bus, stack.keys
        self.world = bus.query(WORLD_DESCRIPTION, None, WorldDescription, 30.0)
        self.boxes = obstacle_boxes(self.world)
        self.discs = [
            (o.centre[0], o.centre[1], math.hypot(o.half_size[0], o.half_size[1]))
            for o in self.world.obstacles
        ]
        self.people_xy = np.array([p.position for p in self.world.people]).reshape(-1, 2)
        self.fp = Footprint.stowed()
        self.status = bus.latest(keys.nav_status, NavStatus, history=4)
        self.odom = bus.fifo(keys.state_truth, StateTruth, maxlen=200_000)
        self.events = bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=100_000)
        self.last: StateTruth | None = None
        self._odom = bus.fifo(keys.odom, Odom, maxlen=200_000)
        self._located = bus.fifo(keys.localization, Localization, maxlen=50_000)
        self._estimates = Estimates()

    def estimates(self) -> dict[str, Any]:
        """The odometry's and the localization's errors against the truth so far."""
        self._drain(None)
        return self._estimates.figures()

    def pose(self) -> tuple[float, float, float]:
        """The base's true pose now (x, y, yaw)."""
        self._drain(None)
        if self.last is None:
            self.last = self.odom.pop(timeout_s=30.0)
        if self.last is None:
            raise RuntimeError("no state_truth from the sim")
        return Pose.of_odom(self.last)

    def _drain(self, g: GoalFigures | None) -> None:
        for o in self._odom.drain():
            self._estimates.odom(o)
        for loc in self._located.drain():
            self._estimates.located(loc)
        for m in self.odom.drain():
            if m.stamp_ns % 20_000_000:
                continue  # the truth ablation sends it with every state: keep 50 Hz
            self._estimates.truth(m)
            if g is not None:
                self._observe(m, g)
            self.last = m
        for w in self.events.drain():
            for e in w.events:
                if g is not None and isinstance(e, RobotContact) and e.other != "floor":
                    g.contacts[e.other] = g.contacts.get(e.other, 0) + 1

    def _observe(self, m: StateTruth, g: GoalFigures) -> None:
        x, y, yaw = Pose.of_odom(m)
        if self.last is not None:
            x0, y0, _ = Pose.of_odom(self.last)
            g.path_m += math.hypot(x - x0, y - y0)
        fp = footprint_corners(x, y, yaw, self.fp)
        reach = self.fp.circumscribed + g.closest_obstacle_m
        for (oid, corners), (cx, cy, radius) in zip(self.boxes, self.discs, strict=True):
            if math.hypot(cx - x, cy - y) - radius > reach:
                continue  # cannot be closer than the closest so far
            d = rect_distance(fp, corners)
            if d < g.closest_obstacle_m:
                g.closest_obstacle_m, g.closest_obstacle = d, oid
        if len(self.people_xy):
            c, s = math.cos(yaw), math.sin(yaw)
            dx, dy = self.people_xy[:, 0] - x, self.people_xy[:, 1] - y
            u, v = c * dx + s * dy, -s * dx + c * dy
            du = np.maximum(np.maximum(u - self.fp.front, -self.fp.back - u), 0.0)
            dv = np.maximum(np.abs(v) - self.fp.half_width, 0.0)
            g.closest_person_m = min(g.closest_person_m, float(np.min(np.hypot(du, dv))))

    def goto(
        self, x: float, y: float, yaw: float, tol_m: float = 0.1, tol_rad: float = 0.1,
        timeout_s: float = 1800.0,
    ) -> GoalFigures:  # fmt: skip
        """Send one pose goal and follow it to its end (or `timeout_s` of wall time)."""
        g = GoalFigures((x, y, yaw))
        self._drain(None)
        goal = PoseGoal(x=x, y=y, yaw=yaw, position_tolerance_m=tol_m, yaw_tolerance_rad=tol_rad)
        wall0 = time.monotonic()
        reply = send_goal(self.stack, goal)
        t0 = self.last.stamp_ns if self.last is not None else 0
        if not reply.accepted:
            g.reason = reply.reason
            return g
        done: NavStatus | None = None
        while time.monotonic() - wall0 < timeout_s:
            self._drain(g)
            st = self.status.get()
            if (
                st is not None
                and st.goal_id == reply.goal_id
                and st.state not in ("active", "idle")
            ):
                done = st
                break
            time.sleep(0.1)
        time.sleep(0.3)
        self._drain(g)
        g.wall_s = time.monotonic() - wall0
        g.state = done.state if done else "timeout (wall)"
        if done is not None:
            g.reason = f"{done.reason}: {done.detail}" if done.reason else done.detail
        end = done.stamp_ns if done else (self.last.stamp_ns if self.last else t0)
        g.sim_s = (end - t0) / 1e9
        px, py, pyaw = self.pose()
        g.final_error_m = math.hypot(px - x, py - y)
        g.final_yaw_error_rad = abs(math.remainder(pyaw - yaw, math.tau))
        return g
