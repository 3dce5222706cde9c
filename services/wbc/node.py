"""The whole-body controller service: the lockstep command participant around the WBC.

Each state it must answer (stamps on its period, `time.participants.wbc.period_s`) gets
one `JointCommand` with the state's stamp. Per tick:

1. inputs due at t: modes (carried by a source's cmd_vel, or on `wbc/mode`) and cmd_vel
   of the obeyed source at stamp + latency (`inputs`), arm goals accepted whose
   `effective_ns` has come (`arm_actions`). In lockstep the tick first waits
   (`UpstreamGate`, at most `UPSTREAM_WAIT_S` of wall time) for the cmd_vel due now from
   the mode's source (the mission sends one every period, with its mode changes) and
   then from the obeyed source: the sim stepped past their tick once they acked it, but
   their ack can reach the sim before their cmd_vel reaches us, and a command applied
   one period late is a different run. Nothing else is waited for;
2. the command: damping in `damp`; otherwise `WholeBodyController.step` with the gait
   command (walk only) and the arm references; a failed QP keeps the last torques for
   one tick, then the stand hold (`safety`) takes over until `recover_ticks` good solves;
3. publish; then, off the critical path, `wbc/status` at `status_hz` and rerun at `log_hz`.

State estimate: none of its own. The base pose and twist come from the sim's
`RobotState` (MuJoCo's free joint, i.e. perfect odometry); joints, jaw angle and
applied torques likewise. A real robot would put a kinematic-inertial estimator here.
Bad inputs never stop the loop: refused goals get a typed `ErrorReply`, a state with NaN
is answered with damping, a gap in the states (stale state) stops the robot.
"""

from __future__ import annotations

import gc
import math
import threading
import time
from collections import deque

import numpy as np

from common import robot
from common.bus import Fifo, RequestError, WaitTimeout
from common.geometry import FloatArray
from common.lockstep import UpstreamGate
from common.messages import Array, ArrayError, as_numpy
from common.messages.base import NS_PER_S
from common.messages.sim import JointCommand, RobotState
from common.messages.wbc import (
    ArmGoal,
    ArmGoalReply,
    ArmGoalRequest,
    CmdVel,
    Reach,
    WbcMode,
    WbcModeName,
    WbcStatus,
)
from common.robot_description import joint_damping, joint_frictionloss
from common.service import Service
from services.wbc.arm_actions import ArmActions, ArmObservation, ArmParams, GoalRefused, check_reach
from services.wbc.controller import WbcCommand, WbcReferences, WbcState, WholeBodyController
from services.wbc.gait import GaitParams
from services.wbc.inputs import CmdVelArbiter, ModeQueue, PoseHistory
from services.wbc.safety import StandHold, damp_command
from services.wbc.telemetry import WbcLogger, tracking_errors
from services.wbc.values import JAW
from services.wbc.wrench import WrenchEstimator

NAME = "wbc"
TCP = robot.TCP_FRAME


_F64 = np.dtype("<f8")
_JOINTS = (len(robot.JOINT_NAMES),)


def _joints_in(array: Array, name: str) -> FloatArray:
    """A joint vector off the wire (a read-only view), checked as `as_numpy` would, fast."""
    if array.dtype != "float64" or tuple(array.shape) != _JOINTS or len(array.data) != 152:
        raise ArrayError(f"{name} must be float64 {_JOINTS}, got {array.dtype} {array.shape}")
    return np.frombuffer(array.data, dtype=_F64)


def _joints_out(x: FloatArray) -> Array:
    """A joint vector on the wire (what `to_wire` does for a float64 (19,), without checks)."""
    return Array("float64", _JOINTS, x.astype(_F64, copy=False).tobytes())


def wbc_state(msg: RobotState) -> WbcState:
    """The controller's view of a state; ArrayError when its joint vectors are malformed."""
    return WbcState(
        q=_joints_in(msg.q, "q"),
        v=_joints_in(msg.v, "v"),
        base_position_in_world=np.array(msg.base_position_in_world),
        base_orientation_xyzw=np.array(msg.base_orientation_xyzw),
        base_linear_velocity_in_world=np.array(msg.base_linear_velocity_in_world),
        base_angular_velocity_in_base=np.array(msg.base_angular_velocity_in_base),
    )


def joint_command(stamp_ns: int, cmd: WbcCommand) -> JointCommand:
    return JointCommand(
        stamp_ns=stamp_ns,
        tau_ff=_joints_out(cmd.tau_ff),
        q_des=_joints_out(cmd.q_des),
        v_des=_joints_out(cmd.v_des),
        kp=_joints_out(cmd.kp),
        kd=_joints_out(cmd.kd),
        source=NAME,
    )


#: How long a tick waits for an upstream cmd_vel (wall s) before it goes on without.
UPSTREAM_WAIT_S = 0.5


class ArbiterFeed:
    """One source's cmd_vel as the arbiter holds it: what `UpstreamGate` waits on. Reading
    it moves what arrived into the arbiter, and the modes they carry into `modes` (the
    WBC's thread only), so the gate is met by the very samples the arbiter will use,
    never by a copy that arrived first."""

    def __init__(
        self,
        fifo: Fifo[CmdVel],
        arbiter: CmdVelArbiter,
        source: str,
        modes: ModeQueue | None = None,
    ) -> None:
        self.fifo, self.arbiter, self.source, self.modes = fifo, arbiter, source, modes

    def _take(self, cmd: CmdVel) -> None:
        self.arbiter.push(cmd)
        if cmd.mode is not None and self.modes is not None:
            self.modes.push(cmd.mode)

    def get(self) -> CmdVel | None:
        for cmd in self.fifo.drain():
            self._take(cmd)
        return self.arbiter.newest(self.source)

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CmdVel:
        deadline = time.monotonic() + timeout_s
        while True:
            newest = self.get()
            if newest is not None and newest.stamp_ns >= stamp_ns:
                return newest
            left = deadline - time.monotonic()
            cmd = self.fifo.pop(timeout_s=left) if left > 0 else None
            if cmd is None:
                raise WaitTimeout(f"no cmd_vel from {self.source} stamped {stamp_ns}")
            self._take(cmd)


class WbcNode:
    """The service's loop and its bookkeeping (mode, fallback, goals, status)."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        w = cfg.wbc
        self.period_ns = cfg.time.period_ns_of(NAME, 1.0 / cfg.time.tick_hz)
        latency = cfg.time.latencies_ns()
        gait = GaitParams(
            v_max=tuple(w.cmd_vel_max),  # type: ignore[arg-type]
            a_max=tuple(w.cmd_vel_accel_max),  # type: ignore[arg-type]
            d_max=tuple(w.cmd_vel_decel_max),  # type: ignore[arg-type]
        )
        self.ctrl = WholeBodyController(gait_params=gait, clock=time.perf_counter)
        self.actions = ArmActions(ArmParams(grip_effort_max_nm=w.grip_effort_max_nm))
        self.arbiter = CmdVelArbiter(latency, round(w.cmd_vel_timeout_s * NS_PER_S))
        self.arbiter.select(w.cmd_vel_source)
        self.modes = ModeQueue(latency.get(w.mode_source, 0))
        self.poses = PoseHistory()
        self.hold = StandHold()
        self.wrench = WrenchEstimator(joint_damping(), joint_frictionloss())
        self.mode: WbcModeName = w.initial_mode
        self.reason = f"started in {self.mode}"
        self.fallback, self.fail_run, self.ok_run, self.qp_failures = False, 0, 0, 0
        self.last_stamp: int | None = None
        self.obs: ArmObservation | None = None
        self.qp_us = self.tick_us = 0.0
        self.status_every = round(NS_PER_S / w.status_hz)
        self.log_every = round(NS_PER_S / w.log_hz)
        self._goal_lock = threading.Lock()
        #: Accepted goals waiting for their tick: (id, goal, effective stamp or -1).
        self._pending: deque[tuple[str, ArmGoal, int]] = deque()
        self._goal_count = 0
        bus, keys = svc.bus, svc.keys
        self.states = bus.latest(keys.state, RobotState, history=4)
        self.cmd_vel = bus.fifo(keys.cmd_vel, CmdVel, maxlen=4096)
        #: cmd_vel into the arbiter, the modes they carry into the queue.
        self.intake = ArbiterFeed(self.cmd_vel, self.arbiter, "", self.modes)
        self.upstream = UpstreamGate(bus, keys, cfg)
        self.mode_source = w.mode_source
        for name in sorted(cfg.time.participants):  # any periodic one may send cmd_vel
            self.upstream.watch(name, ArbiterFeed(self.cmd_vel, self.arbiter, name, self.modes))
        self.late_inputs = 0
        self.mode_in = bus.fifo(keys.wbc_mode, WbcMode, maxlen=256)
        self.commands = bus.publisher(keys.command, JointCommand, "control")
        self.status = bus.publisher(keys.wbc_status, WbcStatus, "data")
        bus.serve(keys.arm_goal, ArmGoalRequest, self._on_goal)
        self.logger = WbcLogger(svc.rec)

    # -- arm goals (the server's thread) --------------------------------------------------

    def _on_goal(self, req: ArmGoalRequest | None, _selector: str) -> ArmGoalReply:
        if req is None:
            raise RequestError("malformed", "an ArmGoalRequest is needed")
        goal, mode = req.goal, self.mode
        if mode == "damp":
            raise RequestError("unavailable", "mode damp: the arm takes no goals")
        if isinstance(goal, Reach):
            if mode != "manipulate":
                raise RequestError("busy", f"mode {mode}: a reach needs mode manipulate")
            try:
                check_reach(goal)
            except GoalRefused as exc:
                raise RequestError("invalid", str(exc)) from None
        with self._goal_lock:
            self._goal_count += 1
            goal_id = f"arm_{self._goal_count}"
            effective = -1 if req.effective_ns is None else req.effective_ns
            self._pending.append((goal_id, goal, effective))
        self.svc.log.info("arm goal %s accepted: %s", goal_id, type(goal).__name__)
        return ArmGoalReply(accepted=True, goal_id=goal_id)

    # -- the loop --------------------------------------------------------------------------

    def run(self) -> None:
        svc = self.svc
        # Everything set up so far (pinocchio, MuJoCo, OSQP, Zenoh) lives as long as the
        # service: out of the collector's reach, a collection costs microseconds, not
        # milliseconds in the middle of a tick.
        gc.collect()
        gc.freeze()
        svc.ready()
        last = -1

        def is_new(state: RobotState) -> bool:
            return state.stamp_ns > last

        while not svc.stopping:
            try:
                msg = self.states.wait(is_new, 0.1)
            except WaitTimeout:
                continue
            last = msg.stamp_ns
            if msg.stamp_ns % self.period_ns:
                continue  # the sim waits for us only on our period
            t0 = time.perf_counter()
            self.tick(msg, t0)

    def tick(self, msg: RobotState, t0: float) -> None:
        t = msg.stamp_ns
        try:
            state = wbc_state(msg)
        except ArrayError as exc:  # no command: the sim's watchdog holds the joints
            self._say(f"state at t={t / NS_PER_S:.3f} s is malformed ({exc}): not answered")
            return
        if not math.isfinite(float(state.q.sum()) + float(state.v.sum())):  # any NaN or inf
            self.commands.put(joint_command(t, damp_command(np.nan_to_num(state.q))))
            self._say(f"state at t={t / NS_PER_S:.3f} s has NaN: damping")
            return
        stale_ns = self.svc.config.wbc.stale_state_s * NS_PER_S
        gap = 0 if self.last_stamp is None else t - self.last_stamp
        if self.obs is None or gap > stale_ns:  # first state, or a gap: hold where it is
            if self.obs is not None:
                self._say(f"stale state: no state for {gap / 1e6:.0f} ms of sim time; stopped")
            self.ctrl.reset(state)
            self._observe(msg)
        dt = gap / NS_PER_S if 0 < gap <= stale_ns else self.period_ns / NS_PER_S
        self.last_stamp = t
        self._inputs(t, state, msg)
        cmd = self._command(t, state, msg, dt)
        self.commands.put(joint_command(t, cmd))
        self.tick_us = (time.perf_counter() - t0) * 1e6
        # Off the critical path: the sim is stepping now.
        self._observe(msg)
        self.poses.add(t, self.ctrl.model.frames[robot.BASE_FRAME].H)
        if t % self.status_every == 0:
            self._publish_status(t, msg)
        if t % self.log_every == 0:
            T_goal = self.actions.T_goal
            self.logger.log(
                t, self.ctrl, cmd.tau_ff, self._errors(), self.qp_us, self.tick_us, T_goal
            )

    def _observe(self, msg: RobotState) -> None:
        m = self.ctrl.model
        self.obs = ArmObservation(
            T_world_tcp=m.frames[TCP].H.copy(),
            q_arm=m.q[19:25].copy(),
            gripper_angle=msg.gripper_angle,
            gripper_velocity=float(m.v[24]),
            gripper_effort=msg.gripper_effort,
        )

    def _inputs(self, t: int, state: WbcState, msg: RobotState) -> None:
        self._upstream(t, self.mode_source)
        self.intake.get()  # whatever came (realtime: nothing was waited for)
        for mode_msg in self.mode_in.drain():
            self.modes.push(mode_msg)
        for mode_msg in self.modes.due(t):
            self._set_mode(mode_msg, t, state)
        self._upstream(t, self.arbiter.source)
        self.intake.get()
        with self._goal_lock:  # goals start at their effective tick, in the order they came
            due = [p for p in self._pending if p[2] <= t]
            self._pending = deque(p for p in self._pending if p[2] > t)
        assert self.obs is not None  # set on the first tick
        for goal_id, goal, _effective in due:
            self.actions.start(goal_id, goal, t, self.obs, self.poses.at)

    def _upstream(self, t: int, producer: str) -> None:
        """Wait for `producer`'s cmd_vel due at t (lockstep; see the module's docstring)."""
        if not self.upstream.wait(t, UPSTREAM_WAIT_S, (producer,)):
            return
        self.late_inputs += 1
        if self.late_inputs in (1, 10, 100) or self.late_inputs % 1000 == 0:
            self._say(
                f"t={t / NS_PER_S:.3f} s: no cmd_vel from {producer} for its tick due now "
                f"within {UPSTREAM_WAIT_S} s ({self.late_inputs} times): went on without it"
            )

    def _set_mode(self, msg: WbcMode, t: int, state: WbcState) -> None:
        self.arbiter.select(msg.cmd_vel_source)
        old, new = self.mode, msg.mode
        if new == old:
            return
        self.mode = new
        assert self.obs is not None
        if new == "damp" or old == "manipulate":
            self.actions.cancel(f"mode {old} -> {new}", t, self.obs, drop_pose=True)
        if old == "damp":
            self.ctrl.reset(state)
        self._say(f"mode {old} -> {new} (cmd_vel from {msg.cmd_vel_source})")

    def _command(self, t: int, state: WbcState, msg: RobotState, dt: float) -> WbcCommand:
        assert self.obs is not None
        arm = self.actions.update(t, self.obs)
        if self.mode == "damp":
            cmd = damp_command(state.q)
            if arm.gripper_effort is not None:
                cmd.tau_ff[JAW] = arm.gripper_effort
            return cmd
        refs = WbcReferences(
            cmd_vel=self.arbiter.command(t) if self.mode == "walk" else np.zeros(3),
            T_world_tcp=arm.T_world_tcp,
            tcp_twist=arm.tcp_twist,
            tcp_acceleration=arm.tcp_acceleration,
            arm_posture=arm.arm_posture,
            gripper_angle=arm.gripper_angle,
            gripper_effort=arm.gripper_effort,
        )
        cmd = self.ctrl.step(state, refs, dt)
        timing = self.ctrl.last_timing
        self.qp_us = (timing.get("build", 0.0) + timing.get("solve", 0.0)) * 1e6
        if cmd.qp_ok:
            self.fail_run = 0
            if self.fallback:
                self.ok_run += 1
                if self.ok_run >= self.svc.config.wbc.recover_ticks:
                    self.fallback = False
                    self.ctrl.reset(state)
                    self._say("QP solves again: whole-body control resumed")
        else:
            self.fail_run += 1
            self.qp_failures += 1
            self.ok_run = 0
            if self.fail_run == 1:
                self._say(f"QP failed ({cmd.qp_status}): holding the last torques")
            elif not self.fallback:
                self.fallback = True
                self.hold.engage(self.ctrl.model)
                self._say(f"QP failed {self.fail_run} ticks: stand hold")
        if self.fallback:
            return self.hold.command(arm.gripper_effort, arm.gripper_angle)
        return cmd

    # -- status ----------------------------------------------------------------------------

    def _say(self, reason: str) -> None:
        self.reason = reason
        self.svc.log.info("%s", reason)

    def _errors(self) -> tuple[float, float, float]:
        return tracking_errors(self.ctrl, self.actions.tracking_pose and self.mode != "damp")

    def _publish_status(self, t: int, msg: RobotState) -> None:
        m = self.ctrl.model
        wrench = self.wrench.update(
            m.h,
            m.v,
            np.asarray(as_numpy(msg.tau), dtype=float),
            m.frame_jacobian(TCP),  # computed here when no task needed it this tick
            m.frames[robot.BASE_FRAME].R,
        )
        base_err, tcp_m, tcp_rad = self._errors()
        self.status.put(
            WbcStatus(
                stamp_ns=t,
                mode=self.mode,
                cmd_vel_source=self.arbiter.source,
                goals=self.actions.statuses(),
                base_error_m=base_err,
                gripper_error_m=tcp_m,
                gripper_error_rad=tcp_rad,
                qp_time_us=self.qp_us,
                qp_failures=self.qp_failures,
                contacts=msg.foot_contacts,
                gripper_angle=msg.gripper_angle,
                gripper_effort=msg.gripper_effort,
                held=self.actions.held,
                gripper_wrench=tuple(float(x) for x in wrench),  # type: ignore[arg-type]
                reason=self.reason,
            )
        )


def main(svc: Service) -> None:
    WbcNode(svc).run()
