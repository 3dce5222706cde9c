"""A person stepping into the robot's path, measured from the sim's truth.

The hall of seed 3 has 6 m of free floor ahead of the robot's start and 3 m to its left.
The robot gets a goal 6 m straight ahead. `person_2` is moved (`dume/world/people_command`)
to 1.2 m left of the path, 4.5 m ahead; once the robot has walked 0.3 m they step into the
path at 1 m/s and stand there, and 1 s after the robot has stood still they step back out.
Their position at every truth sample follows from those commands (straight legs at a
known speed from known stamps; the sim applies each at its stamp). Figures: the closest
approach of the footprint to them, the fastest and slowest 0.5 s mean speed while they
have been within 2 m for that window and a 0.5 s reaction time before it, the length
walked, whether and when they stepped in and out, contacts, the goal's end state.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from bench.nav_run import nav_stack, send_goal
from common.bus import Latest
from common.config import REPO_ROOT, Overrides, merged
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS, WORLD_PEOPLE_COMMAND
from common.messages.navigation import NavStatus, PoseGoal
from common.messages.sim import PersonCommand, RobotContact, StateTruth, WorldEvents
from common.messages.world import WorldDescription
from common.robot import Footprint
from deploy.stack import ProcessStack
from services.navigation.grid import Pose, distance_to_footprint

SETTINGS = {
    "sim.world": "hall",
    "sim.world_seed": 3,
    "perception.segmenter": "truth",  # the ablation: this is about navigation
    "perception.cameras": ["camera_head"],
    "semantic_map.cameras": ["camera_head"],
}
WALK_MPS = 1.0
WINDOW = 25  # samples: 0.5 s at 50 Hz
SAMPLE_NS = 20_000_000  # the base's truth, every 20 ms
Leg = Callable[[int], tuple[float, float] | None]


class Start:
    """Points given ahead (u) and to the left (v) of the robot's start pose, in the world."""

    def __init__(self, x: float, y: float, yaw: float) -> None:
        self.x, self.y, self.yaw = x, y, yaw

    def at(self, u: float, v: float) -> tuple[float, float]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.x + c * u - s * v, self.y + s * u + c * v

    def ahead(self, x: float, y: float) -> float:
        return math.cos(self.yaw) * (x - self.x) + math.sin(self.yaw) * (y - self.y)


def walk_leg(a: tuple[float, float], b: tuple[float, float], t0: int) -> Leg:
    """Where a person walking from a to b from t0 (ns) is at t (None before t0)."""
    length = math.dist(a, b)

    def where(t: int) -> tuple[float, float] | None:
        if t < t0:
            return None
        k = min(1.0, WALK_MPS * (t - t0) / 1e9 / length)
        return a[0] + k * (b[0] - a[0]), a[1] + k * (b[1] - a[1])

    return where


@dataclass
class PersonFigures:
    state: str = ""
    t_in_s: float = 0.0
    t_out_s: float = 0.0
    closest_m: float = math.inf
    fastest_near_mps: float = math.nan
    slowest_near_mps: float = math.nan
    walked_m: float = 0.0
    moving_after_out: bool = False
    contacts: dict[str, int] = field(default_factory=dict)


def person_step_in(s: ProcessStack, timeout_s: float = 1500.0) -> PersonFigures:
    """Run the scenario on a started navigation stack with perception; its figures."""
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 30.0)
    start = Start(world.robot_start.x, world.robot_start.y, world.robot_start.yaw)
    people = s.bus.publisher(WORLD_PEOPLE_COMMAND, PersonCommand, "control")
    side, path = start.at(4.5, 1.2), start.at(4.5, 0.0)
    into, out_of = start.yaw - math.pi / 2, start.yaw + math.pi / 2
    people.put(PersonCommand(stamp_ns=0, person_id="person_2", position=side, yaw=into))
    status: Latest[NavStatus] = s.bus.latest(s.keys.nav_status, NavStatus)
    odom = s.bus.fifo(s.keys.state_truth, StateTruth, maxlen=200_000)  # measured on truth
    events = s.bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=100_000)
    gx, gy = start.at(6.0, 0.0)
    reply = send_goal(s, PoseGoal(x=gx, y=gy, yaw=start.yaw))
    samples: list[StateTruth] = []
    legs: list[Leg] = []
    t_in = t_out = 0
    still_since: int | None = None
    deadline = time.monotonic() + timeout_s
    done: NavStatus | None = None
    while time.monotonic() < deadline and reply.accepted:
        msg = odom.pop(timeout_s=1.0)
        if msg is not None and msg.stamp_ns % SAMPLE_NS:
            continue  # the truth ablation sends it with every state: keep 50 Hz
        if msg is not None:
            samples.append(msg)
            t = msg.stamp_ns
            if not t_in and start.ahead(*msg.base_position_in_world[:2]) >= 0.3:
                t_in = t + 300_000_000  # ahead of the sim: applied at its stamp
                people.put(PersonCommand(stamp_ns=t_in, person_id="person_2", yaw=into,
                                         walk_to=(path,), speed=WALK_MPS))  # fmt: skip
                legs = [walk_leg(side, path, t_in)]
            moving = math.hypot(*msg.base_linear_velocity_in_world[:2]) > 0.05
            if t_in and not t_out and t > t_in:
                still_since = None if moving else (still_since or t)
                if still_since is not None and t - still_since >= 1_000_000_000:
                    t_out = t + 300_000_000
                    people.put(PersonCommand(stamp_ns=t_out, person_id="person_2", yaw=out_of,
                                             walk_to=(side,), speed=WALK_MPS))  # fmt: skip
                    legs.insert(0, walk_leg(path, side, t_out))
        st = status.get()
        if st is not None and st.goal_id == reply.goal_id and st.state not in ("active", "idle"):
            done = st
            break
    samples.extend(m for m in odom.drain() if m.stamp_ns % SAMPLE_NS == 0)
    f = PersonFigures(state=done.state if done else reply.reason or "timeout (wall)")
    f.t_in_s, f.t_out_s = t_in / 1e9, t_out / 1e9
    for w in events.drain():
        for e in w.events:
            if isinstance(e, RobotContact) and e.other != "floor":
                f.contacts[e.other] = f.contacts.get(e.other, 0) + 1
    if len(samples) <= 2 * WINDOW:
        return f
    fp = Footprint.stowed()

    def person_at(t: int) -> tuple[float, float]:
        return next((p for leg in legs if (p := leg(t)) is not None), side)

    dist = np.array([
        float(distance_to_footprint(Pose.of_odom(m), fp, np.array([person_at(m.stamp_ns)]))[0])
        for m in samples
    ])  # fmt: skip
    f.closest_m = float(dist.min())
    xy = np.array([m.base_position_in_world[:2] for m in samples])
    speed = np.hypot(*(xy[WINDOW:] - xy[:-WINDOW]).T) / (WINDOW * 0.02)
    far = dist > 2.0
    near = np.array([not far[max(0, j - WINDOW) : j + WINDOW + 1].any() for j in range(len(speed))])
    if near.any():
        f.fastest_near_mps = float(speed[near].max())
        f.slowest_near_mps = float(speed[near].min())
    f.walked_m = float(np.hypot(*np.diff(xy, axis=0).T).sum())
    after = [m for m in samples if t_out and m.stamp_ns > t_out + 3_000_000_000]
    f.moving_after_out = any(math.hypot(*m.base_linear_velocity_in_world[:2]) > 0.2 for m in after)
    return f


def person_trial(overrides: Overrides | None = None) -> dict[str, Any]:
    """`dume trial person`: the scenario on a fresh stack (hall, seed 3); its figures."""
    wall0 = time.monotonic()
    with nav_stack("hall", 3, merged(SETTINGS, overrides or {}), perception=True) as stack:
        f = person_step_in(stack)
        logs = str(stack.run_dir.relative_to(REPO_ROOT))
    out = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in asdict(f).items()}
    return {"trial": "person", "world": "hall", "world_seed": 3, **out,
            "wall_s": round(time.monotonic() - wall0, 1), "logs": logs}  # fmt: skip
