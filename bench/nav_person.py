"""A person stepping into the robot's path, or walking across it, measured from the truth.

The hall of seed 3 has 6 m of free floor ahead of the robot's start and 3 m to its left.
The robot gets a goal 6 m straight ahead. Two scenarios (`person_2` moved by
`dume/world/people_command`, ignoring the robot):

- `step_in` (`dume trial person`): they stand 1.2 m left of the path, 4.5 m ahead; once
  the robot has walked 0.3 m they step into the path at 1 m/s and stand there, and 1 s
  after the robot has stood still they step back out;
- `crossing` (`dume trial crossing`): they stand 2 m left of the path, 4 m ahead; once
  the robot has walked 1.7 m (its front about 1.8 m from their line) they walk across at
  1 m/s to 2 m right of it and stand there: a bystander who does not stop for the robot.

Their position and velocity at every truth sample follow from those commands (straight
legs at a known speed from known stamps; the sim applies each at its stamp). Figures: the
closest approach of the footprint to them and the robot's speed then, the fastest and
slowest 0.5 s mean speed while they have been within 2 m for that window and a 0.5 s
reaction time before it, the length walked, whether and when they moved, contacts, the
goal's end state; and the speed and separation monitor's own rule judged from truth
(`bench.separation.SeparationWatch`): the samples where the robot moved towards them
closer than the protective separation S_p of its true speed and theirs (`violations`),
and the least margin d − S_p while it moved towards them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from bench.nav_run import nav_stack, send_goal
from bench.separation import SeparationWatch, truth_separation
from common.bus import Latest
from common.config import REPO_ROOT, Overrides, merged
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS, WORLD_PEOPLE_COMMAND
from common.messages.navigation import NavStatus, PoseGoal
from common.messages.sim import (
    PeopleTruth,
    PersonCommand,
    PersonTruth,
    RobotContact,
    StateTruth,
    WorldEvents,
)
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


def leg_velocity(
    a: tuple[float, float], b: tuple[float, float], t0: int
) -> Callable[[int], tuple[float, float] | None]:
    """A walking leg's velocity at t (None before t0; zero once there)."""
    length = math.dist(a, b)
    end = t0 + round(length / WALK_MPS * 1e9)

    def velocity(t: int) -> tuple[float, float] | None:
        if t < t0:
            return None
        if t >= end:
            return 0.0, 0.0
        return WALK_MPS * (b[0] - a[0]) / length, WALK_MPS * (b[1] - a[1]) / length

    return velocity


@dataclass
class PersonFigures:
    state: str = ""
    t_in_s: float = 0.0
    t_out_s: float = 0.0
    closest_m: float = math.inf
    speed_at_closest_mps: float = math.nan
    fastest_near_mps: float = math.nan
    slowest_near_mps: float = math.nan
    walked_m: float = 0.0
    moving_after_out: bool = False
    violations: int = 0
    least_margin_m: float = math.inf
    contacts: dict[str, int] = field(default_factory=dict)


@dataclass
class Walks:
    """A scenario's person: where they stand first, and the legs walked since (newest
    first), each with its velocity."""

    stand: tuple[float, float]
    legs: list[tuple[Leg, Callable[[int], tuple[float, float] | None]]] = field(
        default_factory=list
    )

    def walk(self, a: tuple[float, float], b: tuple[float, float], t0: int) -> None:
        self.legs.insert(0, (walk_leg(a, b, t0), leg_velocity(a, b, t0)))

    def at(self, t: int) -> tuple[float, float]:
        return next((p for leg, _ in self.legs if (p := leg(t)) is not None), self.stand)

    def velocity(self, t: int) -> tuple[float, float]:
        return next((v for _, vel in self.legs if (v := vel(t)) is not None), (0.0, 0.0))


class Scenario:
    """A person's script: `sample` sees each truth sample and commands them; `walks`
    where they were; `t_in`, `t_out` when they moved (ns, 0: not yet)."""

    def __init__(self, start: Start, people: Any, stand: tuple[float, float]) -> None:
        self.start, self.people, self.walks = start, people, Walks(stand)
        self.t_in = self.t_out = 0

    def sample(self, msg: StateTruth) -> None:
        raise NotImplementedError

    def walk(self, t0: int, a: tuple[float, float], b: tuple[float, float], yaw: float) -> None:
        """Command a walk from a to b at t0 (and record it)."""
        self.people.put(PersonCommand(stamp_ns=t0, person_id="person_2", yaw=yaw,
                                      walk_to=(b,), speed=WALK_MPS))  # fmt: skip
        self.walks.walk(a, b, t0)


class StepIn(Scenario):
    """`step_in` (module docstring): into the path at 0.3 m, out 1 s after the robot stood."""

    def __init__(self, start: Start, people: Any) -> None:
        self.side, self.path = start.at(4.5, 1.2), start.at(4.5, 0.0)
        self.into, self.out_of = start.yaw - math.pi / 2, start.yaw + math.pi / 2
        super().__init__(start, people, self.side)
        self.still_since: int | None = None
        people.put(PersonCommand(stamp_ns=0, person_id="person_2", position=self.side,
                                 yaw=self.into))  # fmt: skip

    def sample(self, msg: StateTruth) -> None:
        t = msg.stamp_ns
        if not self.t_in and self.start.ahead(*msg.base_position_in_world[:2]) >= 0.3:
            self.t_in = t + 300_000_000  # ahead of the sim: applied at its stamp
            self.walk(self.t_in, self.side, self.path, self.into)
        moving = math.hypot(*msg.base_linear_velocity_in_world[:2]) > 0.05
        if self.t_in and not self.t_out and t > self.t_in:
            self.still_since = None if moving else (self.still_since or t)
            if self.still_since is not None and t - self.still_since >= 1_000_000_000:
                self.t_out = t + 300_000_000
                self.walk(self.t_out, self.path, self.side, self.out_of)


class Crossing(Scenario):
    """`crossing` (module docstring): across the path at 1.7 m walked, not stopping."""

    def __init__(self, start: Start, people: Any) -> None:
        self.left, self.right = start.at(4.0, 2.0), start.at(4.0, -2.0)
        super().__init__(start, people, self.left)
        people.put(PersonCommand(stamp_ns=0, person_id="person_2", position=self.left,
                                 yaw=start.yaw - math.pi / 2))  # fmt: skip

    def sample(self, msg: StateTruth) -> None:
        if not self.t_in and self.start.ahead(*msg.base_position_in_world[:2]) >= 1.7:
            self.t_in = msg.stamp_ns + 300_000_000
            self.t_out = self.t_in + round(math.dist(self.left, self.right) / WALK_MPS * 1e9)
            self.walk(self.t_in, self.left, self.right, self.start.yaw - math.pi / 2)


SCENARIOS: dict[str, type[StepIn] | type[Crossing]] = {"step_in": StepIn, "crossing": Crossing}


def person_scenario(
    s: ProcessStack, scenario: str = "step_in", timeout_s: float = 1500.0
) -> PersonFigures:
    """Run a scenario on a started navigation stack with perception; its figures."""
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 30.0)
    start = Start(world.robot_start.x, world.robot_start.y, world.robot_start.yaw)
    script = SCENARIOS[scenario](
        start, s.bus.publisher(WORLD_PEOPLE_COMMAND, PersonCommand, "control")
    )
    status: Latest[NavStatus] = s.bus.latest(s.keys.nav_status, NavStatus)
    odom = s.bus.fifo(s.keys.state_truth, StateTruth, maxlen=200_000)  # measured on truth
    events = s.bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=100_000)
    gx, gy = start.at(6.0, 0.0)
    reply = send_goal(s, PoseGoal(x=gx, y=gy, yaw=start.yaw))
    samples: list[StateTruth] = []
    deadline = time.monotonic() + timeout_s
    done: NavStatus | None = None
    while time.monotonic() < deadline and reply.accepted:
        msg = odom.pop(timeout_s=1.0)
        if msg is not None and msg.stamp_ns % SAMPLE_NS:
            continue  # the truth ablation sends it with every state: keep 50 Hz
        if msg is not None:
            samples.append(msg)
            script.sample(msg)
        st = status.get()
        if st is not None and st.goal_id == reply.goal_id and st.state not in ("active", "idle"):
            done = st
            break
    samples.extend(m for m in odom.drain() if m.stamp_ns % SAMPLE_NS == 0)
    f = PersonFigures(state=done.state if done else reply.reason or "timeout (wall)")
    f.t_in_s, f.t_out_s = script.t_in / 1e9, script.t_out / 1e9
    for w in events.drain():
        for e in w.events:
            if isinstance(e, RobotContact) and e.other != "floor":
                f.contacts[e.other] = f.contacts.get(e.other, 0) + 1
    if len(samples) <= 2 * WINDOW:
        return f
    fp = Footprint.stowed()
    walks = script.walks
    watch = SeparationWatch(truth_separation(), fp)
    for m in samples:
        t = m.stamp_ns
        there = PersonTruth(
            id="person_2", position=walks.at(t), yaw=0.0, velocity=walks.velocity(t)
        )
        watch.add(m, PeopleTruth(stamp_ns=t, people=[there]))
    f.violations, f.least_margin_m = watch.violations, watch.least_margin_m
    f.closest_m, f.speed_at_closest_mps = watch.closest_m, watch.speed_at_closest_mps
    dist = np.array([
        float(distance_to_footprint(Pose.of_odom(m), fp, np.array([walks.at(m.stamp_ns)]))[0])
        for m in samples
    ])  # fmt: skip
    xy = np.array([m.base_position_in_world[:2] for m in samples])
    speed = np.hypot(*(xy[WINDOW:] - xy[:-WINDOW]).T) / (WINDOW * 0.02)
    far = dist > 2.0
    near = np.array([not far[max(0, j - WINDOW) : j + WINDOW + 1].any() for j in range(len(speed))])
    if near.any():
        f.fastest_near_mps = float(speed[near].max())
        f.slowest_near_mps = float(speed[near].min())
    f.walked_m = float(np.hypot(*np.diff(xy, axis=0).T).sum())
    after = [m for m in samples if script.t_out and m.stamp_ns > script.t_out + 3_000_000_000]
    f.moving_after_out = any(math.hypot(*m.base_linear_velocity_in_world[:2]) > 0.2 for m in after)
    return f


def person_trial(overrides: Overrides | None = None, scenario: str = "step_in") -> dict[str, Any]:
    """`dume trial person` (step_in) or `crossing`: the scenario on a fresh stack (hall,
    seed 3); its figures."""
    wall0 = time.monotonic()
    with nav_stack("hall", 3, merged(SETTINGS, overrides or {}), perception=True) as stack:
        f = person_scenario(stack, scenario)
        logs = str(stack.run_dir.relative_to(REPO_ROOT))
    out = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in asdict(f).items()}
    name = "person" if scenario == "step_in" else scenario
    return {"trial": name, "world": "hall", "world_seed": 3, **out,
            "wall_s": round(time.monotonic() - wall0, 1), "logs": logs}  # fmt: skip
