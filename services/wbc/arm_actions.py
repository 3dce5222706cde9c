"""The arm action API's state machine: Reach, Grasp, Release and Posture goals.

Nobody else sequences the arm: the node hands every accepted goal to `ArmActions`, which
turns it into the controller's arm references each tick and keeps each goal's state
(active → succeeded / failed with a reason / cancelled when preempted). One goal is
active at a time; a new one preempts it, and the arm then holds the reference it had
reached (a frozen pose or joint target), so Grasp after Reach keeps the gripper there.

- Reach: the goal ᴮH_G or ᵂH_G becomes ᵂH_G with the base pose at the goal's stamp
  (fixed in the world from then on); the TCP moves there along minimum-jerk segments, via
  a pre-grasp pose `pregrasp_m` back along the approach axis; it succeeds when within
  `reach_tol_m` and `reach_tol_rad` after the motion (`held_tol_*` while gripping: the
  controller's model does not know the payload; its integral action takes the sag out
  within about a second, not at once), fails after `settle_s` more. Reach opens the jaw
  (as wide as its `jaw` says) unless it is gripping.
- Grasp: close under min(max_effort, `wbc.grip_effort_max_nm`) until `GraspDetector` says held
  (succeeded) or the jaw closes on nothing or `grasp_timeout_s` passes (failed).
- Release: open the jaw; succeeded once open (or after `release_s`).
- Posture(name): the arm joints move to `common.robot.POSTURES[name]` on a quintic; the
  jaw takes the posture's angle unless it is gripping.

A Reach's or a Posture's `speed` (0, 1] scales its speeds and rates (the mission slows
the arm near people); the tolerances and timeouts run from the motion's end as before.

Pure: plain values in and out, time from the caller (ns of sim time).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from common import robot
from common.config import WbcSettings
from common.geometry import FloatArray
from common.messages.base import NS_PER_S
from common.messages.wbc import ArmGoal, GoalState, GoalStatus, Grasp, Posture, Reach, Release
from services.wbc.gait import quintic
from services.wbc.grasp import GraspDetector, GraspParams
from services.wbc.reach import PoseSample, PoseSegment, pregrasp
from services.wbc.values import ARM


class GoalRefused(Exception):
    """A goal that cannot start: the reason, for the ArmGoalReply."""


@dataclass(frozen=True)
class ArmParams:
    """Speeds (m/s, rad/s), tolerances and timeouts (s). Not settings: tuned with the arm
    and the gripper (the grip torque cap is `wbc.grip_effort_max_nm`)."""

    reach_speed_m_s: float = 0.4
    reach_rate_rad_s: float = 1.5
    approach_speed_m_s: float = 0.1
    joint_rate_rad_s: float = 1.0
    min_segment_s: float = 0.5
    reach_tol_m: float = 0.01
    reach_tol_rad: float = math.radians(3.0)
    held_tol_m: float = 0.03  # while gripping: the model does not know the payload
    held_tol_rad: float = math.radians(6.0)
    posture_tol_rad: float = 0.05
    held_posture_tol_rad: float = 0.15
    settle_s: float = 2.0
    grasp_timeout_s: float = 3.0
    release_s: float = 1.5
    grasp: GraspParams = field(default_factory=GraspParams)


@dataclass
class ArmObservation:
    """What the arm looks like now: TCP pose in world (4×4), arm joints (6,), the jaw."""

    T_world_tcp: FloatArray
    q_arm: FloatArray
    gripper_angle: float
    gripper_velocity: float
    gripper_effort: float


@dataclass
class ArmReferences:
    """The controller's arm references (see `values.WbcReferences`)."""

    T_world_tcp: FloatArray | None
    tcp_twist: FloatArray | None
    tcp_acceleration: FloatArray | None
    arm_posture: FloatArray
    gripper_angle: float
    gripper_effort: float | None


@dataclass
class _Goal:
    goal_id: str
    kind: str
    state: GoalState = "active"
    reason: str = ""
    start_ns: int = 0
    miss_m: float = 0.0

    def status(self) -> GoalStatus:
        return GoalStatus(
            goal_id=self.goal_id,
            kind=self.kind,
            state=self.state,
            reason=self.reason,
            miss_m=self.miss_m,
        )


def pose_error(T_a: FloatArray, T_b: FloatArray) -> tuple[float, float]:
    """Distance (m) and rotation angle (rad) between two poses."""
    dp = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    return dp, float(np.linalg.norm(pin.log3(T_a[:3, :3].T @ T_b[:3, :3])))


def check_reach(goal: Reach) -> None:
    """Refuse a Reach whose H is not a rigid transform or whose approach axis is null."""
    H = np.array(goal.H, dtype=float).reshape(4, 4)
    R = H[:3, :3]
    if not np.allclose(H[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise GoalRefused(f"H's last row must be 0 0 0 1, got {H[3].tolist()}")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0.0:
        raise GoalRefused("H's rotation is not orthonormal with det +1")
    if np.linalg.norm(goal.approach_axis) < 0.5:
        raise GoalRefused(f"approach_axis {goal.approach_axis} is not a unit vector")


class ArmActions:
    """Goals in, arm references out; `statuses()` for `wbc/status`."""

    def __init__(
        self, settings: WbcSettings, params: ArmParams | None = None, keep: int = 8
    ) -> None:
        self.settings = settings
        self.params = p = params or ArmParams()
        self.detector = GraspDetector(p.grasp)
        self._keep = keep
        self._goals: OrderedDict[str, _Goal] = OrderedDict()
        self.active: _Goal | None = None
        # The arm: a joint motion (posture) or pose segments (reach), sampled by time.
        self._q_from: FloatArray = robot.POSTURES["stand"][ARM].copy()
        self._q_to: FloatArray = self._q_from.copy()
        self._q_t0, self._q_dur = 0, 1.0
        self._segments: list[tuple[int, PoseSegment]] = []
        self.T_goal: FloatArray | None = None  # the Reach's final pose, world
        self._T_hold: FloatArray | None = None  # a pose held after a preempted reach
        # The jaw: "open" / "closed" by angle, or "grip" under a torque limit.
        self.jaw = "closed"
        self._jaw_angle = robot.GRIPPER_CLOSED
        self._grip_nm = 0.0
        self._last_ns: int | None = None

    # -- goals --------------------------------------------------------------------------

    def start(
        self,
        goal_id: str,
        goal: ArmGoal,
        now_ns: int,
        obs: ArmObservation,
        T_world_base_at: Callable[[int], FloatArray | None],
    ) -> None:
        """Start an accepted goal (preempting the active one); it may fail at once."""
        record = _Goal(goal_id, type(goal).__name__.lower(), start_ns=now_ns)
        self._preempt(f"preempted by {goal_id}", now_ns, obs)
        self._goals[goal_id] = record
        while len(self._goals) > self._keep:
            self._goals.popitem(last=False)
        self.active = record
        if isinstance(goal, Reach):
            self._start_reach(goal, now_ns, obs, T_world_base_at)
        elif isinstance(goal, Grasp):
            self.jaw, self._grip_nm = "grip", min(goal.max_effort, self.settings.grip_effort_max_nm)
            self.detector.reset()
        elif isinstance(goal, Release):
            self.jaw, self._jaw_angle = "open", robot.GRIPPER_OPEN
        elif isinstance(goal, Posture):
            self._start_joints(robot.POSTURES[goal.name][ARM], now_ns, obs.q_arm, goal.speed)
            if self.jaw != "grip":
                angle = float(robot.POSTURES[goal.name][-1])
                self.jaw = "open" if angle < robot.GRIPPER_CLOSED - 0.1 else "closed"
                self._jaw_angle = angle

    def _start_reach(
        self,
        goal: Reach,
        now_ns: int,
        obs: ArmObservation,
        T_world_base_at: Callable[[int], FloatArray | None],
    ) -> None:
        H = np.array(goal.H, dtype=float).reshape(4, 4)
        if goal.frame == "base":
            T_wb = T_world_base_at(goal.stamp_ns)
            if T_wb is None:
                self._end("failed", f"no base pose at the goal's stamp {goal.stamp_ns} ns")
                return
            H = T_wb @ H
        p = self.params
        axis = np.asarray(goal.approach_axis, dtype=float)
        waypoints = [H] if goal.pregrasp_m <= 0.0 else [pregrasp(H, goal.pregrasp_m, axis), H]
        self._segments, t0, T_prev = [], now_ns, obs.T_world_tcp.copy()
        for k, T in enumerate(waypoints):
            dist, angle = pose_error(T_prev, T)
            speed = (p.approach_speed_m_s if k == 1 else p.reach_speed_m_s) * goal.speed
            rate = p.reach_rate_rad_s * goal.speed
            duration = max(dist / speed, angle / rate, p.min_segment_s)
            self._segments.append((t0, PoseSegment(T_prev, T, duration)))
            t0 += round(duration * NS_PER_S)
            T_prev = T
        self.T_goal, self._T_hold = H, None
        if self.jaw != "grip":
            wide = goal.jaw == "wide"
            self.jaw, self._jaw_angle = "open", robot.GRIPPER_WIDE if wide else robot.GRIPPER_OPEN

    def _start_joints(
        self, q_goal: FloatArray, now_ns: int, q_now: FloatArray, speed: float = 1.0
    ) -> None:
        self._segments, self.T_goal, self._T_hold = [], None, None
        self._q_from, self._q_to = np.array(q_now, dtype=float), np.array(q_goal, dtype=float)
        span = float(np.max(np.abs(self._q_to - self._q_from)))
        self._q_t0 = now_ns
        rate = self.params.joint_rate_rad_s * speed
        self._q_dur = max(span / rate, self.params.min_segment_s)

    def _preempt(self, reason: str, now_ns: int, obs: ArmObservation) -> None:
        """End the active goal; the arm keeps the reference it reached."""
        if self.active is not None and self.active.state == "active":
            self._end("cancelled", reason)
        if self._segments:
            end_ns = self._segments[-1][0] + round(self._segments[-1][1].duration * NS_PER_S)
            if now_ns < end_ns:  # mid-motion: freeze where the reference is
                self._T_hold = self._sample_pose(now_ns).T
                self._segments = []

    def cancel(self, reason: str, now_ns: int, obs: ArmObservation, drop_pose: bool) -> None:
        """Cancel the active goal; with `drop_pose` the arm holds its joints where they are
        (leaving manipulate: no TCP target in the world while walking)."""
        self._preempt(reason, now_ns, obs)
        if drop_pose and (self._segments or self._T_hold is not None or self.T_goal is not None):
            self._start_joints(obs.q_arm, now_ns, obs.q_arm)

    def _end(self, state: GoalState, reason: str = "", miss_m: float = 0.0) -> None:
        if self.active is not None:
            self.active.state, self.active.reason = state, reason
            self.active.miss_m = miss_m if math.isfinite(miss_m) else 0.0
            self.active = None

    def statuses(self) -> list[GoalStatus]:
        return [g.status() for g in self._goals.values()]

    @property
    def held(self) -> bool:
        return self.detector.held

    @property
    def tracking_pose(self) -> bool:
        return bool(self._segments) or self._T_hold is not None

    # -- each tick ----------------------------------------------------------------------

    def _sample_pose(self, now_ns: int) -> PoseSample:
        t0, seg = self._segments[0]
        for start, s in self._segments:
            if now_ns >= start:
                t0, seg = start, s
        return seg.sample((now_ns - t0) / NS_PER_S)

    def update(self, now_ns: int, obs: ArmObservation) -> ArmReferences:
        """The references for this tick; advances the active goal's state."""
        dt = 0.0 if self._last_ns is None else (now_ns - self._last_ns) / NS_PER_S
        self._last_ns = now_ns
        closing = self.jaw == "grip"
        self.detector.update(
            closing, obs.gripper_angle, obs.gripper_velocity, obs.gripper_effort, dt
        )
        self._advance(now_ns, obs)
        T = twist = acc = None
        if self._segments:
            sample = self._sample_pose(now_ns)
            T, twist, acc = sample.T, sample.twist, sample.acceleration
        elif self._T_hold is not None:
            T, twist, acc = self._T_hold, np.zeros(6), np.zeros(6)
        s, _, _ = quintic((now_ns - self._q_t0) / NS_PER_S / self._q_dur)
        posture = self._q_from + s * (self._q_to - self._q_from)
        return ArmReferences(
            T_world_tcp=T,
            tcp_twist=twist,
            tcp_acceleration=acc,
            arm_posture=posture,
            gripper_angle=robot.GRIPPER_OPEN if closing else self._jaw_angle,
            gripper_effort=self._grip_nm if closing else None,
        )

    def _advance(self, now_ns: int, obs: ArmObservation) -> None:
        goal, p = self.active, self.params
        if goal is None:
            return
        elapsed = (now_ns - goal.start_ns) / NS_PER_S
        if goal.kind == "reach" and self.T_goal is not None and self._segments:
            t_end, seg = self._segments[-1]
            motion_s = (t_end - goal.start_ns) / NS_PER_S + seg.duration
            dist, angle = pose_error(obs.T_world_tcp, self.T_goal)
            gripping = self.jaw == "grip"
            tol_m = p.held_tol_m if gripping else p.reach_tol_m
            tol_rad = p.held_tol_rad if gripping else p.reach_tol_rad
            if elapsed >= motion_s and dist < tol_m and angle < tol_rad:
                self._end("succeeded")
            elif elapsed > motion_s + p.settle_s:
                self._end(
                    "failed",
                    f"gripper_tcp {dist * 100:.1f} cm / {math.degrees(angle):.1f} deg from "
                    f"the goal {elapsed:.1f} s after the start",
                    miss_m=dist,
                )
        elif goal.kind == "posture":
            err = float(np.max(np.abs(obs.q_arm - self._q_to)))
            tol = p.held_posture_tol_rad if self.jaw == "grip" else p.posture_tol_rad
            if elapsed >= self._q_dur and err < tol:
                self._end("succeeded")
            elif elapsed > self._q_dur + p.settle_s:
                off = np.abs(obs.q_arm - self._q_to)
                joints = ", ".join(f"joint{k + 1} at {obs.q_arm[k]:+.2f} for {self._q_to[k]:+.2f}"
                                   for k in np.argsort(-off) if off[k] >= tol)  # fmt: skip
                self._end("failed", f"arm {err:.3f} rad from the posture after {elapsed:.1f} "
                          f"s ({joints})")  # fmt: skip
        elif goal.kind == "grasp":
            if self.detector.held:
                self._end("succeeded")
            elif self.detector.empty:
                self.jaw, self._jaw_angle = "closed", robot.GRIPPER_CLOSED
                where = ""
                if self.T_goal is not None:  # the reach's goal: did the arm get there?
                    dist, angle = pose_error(obs.T_world_tcp, self.T_goal)
                    where = (f", the TCP {dist * 100:.1f} cm / {math.degrees(angle):.1f} deg "
                             "from the reach's goal")  # fmt: skip
                self._end("failed", f"the jaw closed on nothing{where}")
            elif elapsed > p.grasp_timeout_s:
                self._end("failed", f"no grasp after {elapsed:.1f} s (jaw still moving)")
        elif goal.kind == "release" and (
            obs.gripper_angle < robot.GRIPPER_OPEN + 0.1 or elapsed > p.release_s
        ):
            self._end("succeeded")
