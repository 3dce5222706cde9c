"""The trials' driver: a lockstep participant that scripts the robot over a real stack.

`start_stack` runs router + sim + wbc as processes (`ProcessStack`), lockstep, dynamic
locomotion, cameras off, with the driver registered as the periodic participant `trial`
(every 20 ms, its outputs taking effect 20 ms later), so a trial is as repeatable as
the stack. `Driver.run(script)` steps a generator script once per driver tick: before
each step the driver has the tick's odom and `wbc/status` (`odom`, `status`), and the
script publishes through `cmd`, `mode`, `goal` and `push`, then yields; the driver acks
the tick. A push is stamped two driver periods ahead: the sim reaches that time only
after the driver's next ack, by when the push has long arrived, so it lands on its stamp.
The driver keeps, for every trial, from the sim's truth (`state_truth`): the fall
figures (lowest base, largest roll/pitch), what the robot touched in the world (contact
events, the floor aside) and how far the robot's own odometry is from it
(`EstimateErrors`). Scripts steer by the robot's `odom` (`base`), as the robot would.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Generator, Sequence
from typing import Any

import numpy as np

from bench.estimate_errors import EstimateErrors
from common.bus import Bus
from common.clients import ArmClient, Refused
from common.config import Overrides, merged
from common.geometry import FloatArray, quat_xyzw_to_matrix
from common.keys import WORLD_EVENTS, WORLD_PUSH
from common.lockstep import PeriodicTicker
from common.messages.base import NS_PER_S
from common.messages.sim import Odom, Push, RobotContact, StateTruth, WorldEvents
from common.messages.wbc import ArmGoal, CmdVel, WbcMode, WbcStatus
from common.messages.wbc import GoalStatus as GoalState
from deploy.stack import ProcessStack

log = logging.getLogger(__name__)

NAME = "trial"
PERIOD_S = 0.02
FELL_HEIGHT_M = 0.3
FELL_TILT_DEG = 30.0
Script = Generator[None, None, None]


def trial_settings(world: str, seed: int, wbc_period_s: float) -> dict[str, Any]:
    """Stack settings of a trial: lockstep, dynamic, no cameras, wbc + the driver."""
    return {
        "sim.world": world,
        "sim.world_seed": seed,
        "sim.locomotion": "dynamic",
        "sim.cameras": [],
        "time.mode": "lockstep",
        "time.participants": {
            "wbc": {"role": "command", "period_s": wbc_period_s, "latency_s": 0.0},
            NAME: {"role": "periodic", "period_s": PERIOD_S, "latency_s": PERIOD_S},
        },
        "wbc.cmd_vel_source": NAME,
        "recording.enabled": False,
    }


def start_stack(
    world: str, seed: int, wbc_period_s: float, extra: Overrides | None = None
) -> ProcessStack:
    return ProcessStack(
        ["sim", "wbc"], merged(trial_settings(world, seed, wbc_period_s), extra or {})
    )


def rpy(quat_xyzw: Sequence[float]) -> FloatArray:
    R = quat_xyzw_to_matrix(np.asarray(quat_xyzw, dtype=float))
    return np.array(
        [
            math.atan2(R[2, 1], R[2, 2]),
            -math.asin(max(-1.0, min(1.0, R[2, 0]))),
            math.atan2(R[1, 0], R[0, 0]),
        ]
    )


class Driver:
    """The trial's side of the bus; see the module docstring."""

    def __init__(self, stack: ProcessStack) -> None:
        self.stack = stack
        bus: Bus = stack.bus
        keys = stack.keys
        self.bus, self.keys = bus, keys
        self.stop = threading.Event()
        self._odom = bus.latest(keys.odom, Odom, history=16)
        #: At 50 Hz, or with every state (the WBC's truth ablation): a second's worth.
        self._truth = bus.latest(keys.state_truth, StateTruth, history=512)
        self.estimate = EstimateErrors()
        self._status = bus.latest(keys.wbc_status, WbcStatus, history=16)
        self._cmd = bus.publisher(keys.cmd_vel, CmdVel, "control")
        self._mode = bus.publisher(keys.wbc_mode, WbcMode, "control")
        self._push = bus.publisher(WORLD_PUSH, Push, "control")
        self.arm = ArmClient(bus, keys, 5.0)
        self._events = bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=100_000)
        self.contacts: dict[str, int] = {}  # what the robot touched (truth): other → count
        self.ticker = PeriodicTicker(bus, keys, NAME, PERIOD_S, self.stop)
        self.t_ns = 0
        self.odom: Odom | None = None
        self.truth: StateTruth | None = None
        self.status: WbcStatus | None = None
        self.velocity = (0.0, 0.0, 0.0)
        self.min_height_m = math.inf
        self.max_tilt_deg = 0.0
        self.fell = False

    @property
    def t(self) -> float:
        return self.t_ns / NS_PER_S

    # -- what a script does ---------------------------------------------------------------

    def cmd(self, vx: float, vy: float = 0.0, wz: float = 0.0) -> None:
        """The base velocity from now on (sent every tick, stamped with the tick)."""
        self.velocity = (vx, vy, wz)

    def mode(self, mode: Any) -> None:
        self._mode.put(WbcMode(stamp_ns=self.t_ns, mode=mode, cmd_vel_source=NAME))

    def push(self, force_in_world: Sequence[float], duration_s: float) -> int:
        """Push the base (truth-side test hook); the sim time it lands, ns."""
        stamp = self.t_ns + 2 * round(PERIOD_S * NS_PER_S)
        fx, fy, fz = (float(f) for f in force_in_world)
        self._push.put(Push(stamp_ns=stamp, force_in_world=(fx, fy, fz), duration_s=duration_s))
        return stamp

    def goal(self, goal: ArmGoal) -> str:
        """The goal's id; "" when the controller refused it (logged)."""
        try:
            return self.arm.send(goal)
        except Refused as exc:
            log.warning("arm goal %s refused: %s", type(goal).__name__, exc)
            return ""

    def goal_state(self, goal_id: str) -> GoalState | None:
        if self.status is None:
            return None
        return next((g for g in self.status.goals if g.goal_id == goal_id), None)

    def wait(self, seconds: float) -> Script:
        end = self.t + seconds
        while self.t < end - 1e-9:
            yield

    def finish(self, goal_id: str, timeout_s: float) -> Generator[None, None, GoalState | None]:
        """Wait until the goal is no longer active (or the timeout); its last state."""
        end = self.t + timeout_s
        while self.t < end:
            g = self.goal_state(goal_id)
            if g is not None and g.state != "active":
                return g
            yield
        return self.goal_state(goal_id)

    # -- the loop ---------------------------------------------------------------------------

    def start(self) -> None:
        self.bus.declare_alive(self.keys.alive(NAME))

    def run(self, script: Script, timeout_s: float = 600.0) -> None:
        """Step `script` once per tick until it ends or the robot falls; it starts when the
        robot's odometry has calibrated at rest (at once with the truth ablation)."""
        started = False
        for stamp in self.ticker.ticks():
            self.t_ns = stamp
            self.odom = self._odom.wait_stamp(stamp, timeout_s)
            self.status = self._status.wait_stamp(stamp, timeout_s)
            self._truth.wait_stamp(stamp, timeout_s)
            self.truth = self._truth.at(stamp)
            assert self.truth is not None and self.truth.stamp_ns == stamp, self.truth
            self._check_fall(self.truth)
            self.estimate.add(self.odom, self.truth)
            for events in self._events.drain():
                for e in events.events:
                    if isinstance(e, RobotContact) and e.other != "floor":
                        self.contacts[e.other] = self.contacts.get(e.other, 0) + 1
            vx, vy, wz = self.velocity
            self._cmd.put(CmdVel(stamp_ns=stamp, vx=vx, vy=vy, wz=wz, source=NAME))
            if not started and self.status.calibrating:  # the robot's IMU, at rest
                self.ticker.ack(stamp)
                continue
            started = True
            try:
                next(script)
            except StopIteration:
                self.ticker.ack(stamp)
                return
            self.ticker.ack(stamp)
            if self.fell:
                return

    def _check_fall(self, truth: StateTruth) -> None:
        z = truth.base_position_in_world[2]
        tilt = float(np.degrees(np.max(np.abs(rpy(truth.base_orientation_xyzw)[:2]))))
        self.min_height_m = min(self.min_height_m, z)
        self.max_tilt_deg = max(self.max_tilt_deg, tilt)
        self.fell = self.fell or z < FELL_HEIGHT_M or tilt > FELL_TILT_DEG

    def base(self, truth: bool = False) -> tuple[FloatArray, float]:
        """Base xy (2,) and yaw now: as the robot's odometry has them, or (`truth`) as the
        sim does, for the figures."""
        state = self.truth if truth else self.odom
        assert state is not None
        p = np.array(state.base_position_in_world[:2])
        return p, float(rpy(state.base_orientation_xyzw)[2])

    def figures(self) -> dict[str, Any]:
        return {
            "fell": self.fell,
            "sim_s": round(self.t, 3),
            "min_base_height_m": round(self.min_height_m, 4),
            "max_roll_pitch_deg": round(self.max_tilt_deg, 2),
            "qp_failures": 0 if self.status is None else self.status.qp_failures,
            "robot_contacts": dict(sorted(self.contacts.items())),
            "odometry": self.estimate.figures(),
        }
