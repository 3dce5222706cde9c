"""The WBC's work each tick, off the bus: mode changes, arm goals, the command, the status.

`WbcCommander` owns the controller and its bookkeeping; the node feeds it what came over
the bus and publishes what it returns. A tick, all on the WBC's thread, in this order:

1. `begin(t, state, msg)`: with `wbc.base_state = "estimate"`, the odometry predicts the
   base at t and the state carries it (`odometry`); the first state, or one after a gap
   over `stale_state_s` (sim time), resets the controller to hold where the robot is;
   returns the state and dt (s);
2. the node pushes the cmd_vel and `wbc/mode` samples that came into `arbiter` and
   `modes`; `apply_modes(t, state)` applies the modes due at t (`set_mode`), and
   `start_goals(t)` starts the arm goals due at t (`goals`) in the order they came;
3. `command(t, state, dt)`: damping in mode `damp`; otherwise the controller's step with
   the cmd_vel (walk only; zero while the odometry calibrates at start-up) and the arm
   references, through the QP-failure `fallback`;
4. after the publish: `end(t, msg)` corrects the odometry from the legs, observes the
   arm and records the base pose; `status` and `errors` for `wbc/status` and rerun.

Units: stamps ns of sim time, poses in world (4×4; odom when estimating), cmd_vel (vx,
vy, ωz) m/s and rad/s in `base_yaw`. Threads: `goals.accept` runs on the query server's
thread and reads `mode` (an attribute read, no lock); everything else is the WBC's
thread only.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping

import numpy as np

from common import robot
from common.config import WbcSettings
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.sim import RobotState
from common.messages.wbc import WbcMode, WbcModeName, WbcStatus
from common.robot_description import joint_damping, joint_frictionloss
from services.wbc.arm_actions import ArmActions, ArmObservation
from services.wbc.controller import WbcCommand, WbcReferences, WbcState, WholeBodyController
from services.wbc.fallback import QpFallback
from services.wbc.goals import GoalIntake
from services.wbc.inputs import CmdVelArbiter, ModeQueue, PoseHistory
from services.wbc.odometry import LegOdometry, Pose2
from services.wbc.safety import damp_command
from services.wbc.telemetry import tracking_errors
from services.wbc.values import JAW, Q_ARM, V_JAW
from services.wbc.wrench import WrenchEstimator

TCP = robot.TCP_FRAME


class WbcCommander:
    """The controller, its inputs' bookkeeping, the mode, the arm, the fallback, the status.

    `mode` is the current mode and `reason` the last thing said (`say`); `obs` the arm as
    of the last `end` (None before the first tick); `qp_us` the last QP's build and solve
    time (µs of wall time). `period_ns` is the tick's period, the dt after a gap.
    `odometry` is the base's estimate (None when the state's base is used: the truth
    ablation); it starts at `start` (x, y, yaw).
    """

    def __init__(
        self,
        w: WbcSettings,
        latency: Mapping[str, int],
        period_ns: int,
        log: logging.Logger,
        start: Pose2 | None = None,
    ) -> None:
        self.log, self.period_ns = log, period_ns
        self.ctrl = WholeBodyController(gait=w.gait, clock=time.perf_counter)
        self.actions = ArmActions(w)
        self.arbiter = CmdVelArbiter(latency, round(w.cmd_vel_timeout_s * NS_PER_S))
        self.arbiter.select(w.cmd_vel_source)
        self.modes = ModeQueue(latency.get(w.mode_source, 0))
        self.poses = PoseHistory()
        self.fallback = QpFallback(self.ctrl, w.recover_ticks, self.say)
        self.wrench = WrenchEstimator(joint_damping(), joint_frictionloss())
        self.stale_ns = w.stale_state_s * NS_PER_S
        self.mode: WbcModeName = w.initial_mode
        self.reason = f"started in {self.mode}"
        self.last_stamp: int | None = None
        self.obs: ArmObservation | None = None
        self.qp_us = 0.0
        self.goals = GoalIntake(lambda: self.mode, log)
        self.odometry: LegOdometry | None = None
        self.calibrate_timeout_ns = round(w.estimator.calibrate_timeout_s * NS_PER_S)
        if w.base_state == "estimate":
            self.odometry = LegOdometry(w.estimator, start or (0.0, 0.0, 0.0))

    def say(self, reason: str) -> None:
        """Log `reason` and make it the status's reason."""
        self.reason = reason
        self.log.info("%s", reason)

    # -- a tick ---------------------------------------------------------------------------

    def begin(self, t: int, state: WbcState, msg: RobotState) -> tuple[WbcState, float]:
        """Start the tick of the (well-formed, finite) state at t: the state the controller
        runs on (the base estimated, with odometry) and dt (s) since the last tick."""
        gap = 0 if self.last_stamp is None else t - self.last_stamp
        dt = gap / NS_PER_S if 0 < gap <= self.stale_ns else self.period_ns / NS_PER_S
        if self.odometry is not None:  # over a gap, too: the base kept moving
            standing = not self.ctrl.gait.walking
            state = self.odometry.predict(
                msg, state, gap / NS_PER_S or dt, self.ctrl.model, standing
            )
        if self.obs is None or gap > self.stale_ns:  # first state, or a gap: hold where it is
            if self.obs is not None:
                self.say(f"stale state: no state for {gap / 1e6:.0f} ms of sim time; stopped")
            self.ctrl.reset(state)
            self.observe(msg)
        self.last_stamp = t
        return state, dt

    def observe(self, msg: RobotState) -> None:
        """The arm as the model (updated this tick) and the state's gripper show it."""
        m = self.ctrl.model
        self.obs = ArmObservation(
            T_world_tcp=m.frames[TCP].H.copy(),
            q_arm=m.q[Q_ARM].copy(),
            gripper_angle=msg.gripper_angle,
            gripper_velocity=float(m.v[V_JAW]),
            gripper_effort=msg.gripper_effort,
        )

    def apply_modes(self, t: int, state: WbcState) -> None:
        """Apply the modes in `modes` due at t, in order."""
        for mode_msg in self.modes.due(t):
            self.set_mode(mode_msg, t, state)

    def set_mode(self, msg: WbcMode, t: int, state: WbcState) -> None:
        """Obey the mode's cmd_vel source; on a change of mode, entering damp or leaving
        manipulate cancels the arm's goal (the arm holds its joints), leaving damp resets
        the controller to the state."""
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
        self.say(f"mode {old} -> {new} (cmd_vel from {msg.cmd_vel_source})")

    def start_goals(self, t: int) -> None:
        """Start the accepted arm goals effective at or before t, in the order they came."""
        due = self.goals.due(t)
        assert self.obs is not None  # set on the first tick
        for goal_id, goal, _effective in due:
            self.actions.start(goal_id, goal, t, self.obs, self.poses.at)

    def command(self, t: int, state: WbcState, dt: float) -> WbcCommand:
        """This tick's joint command (`dt` s since the last tick)."""
        assert self.obs is not None
        arm = self.actions.update(t, self.obs)
        if self.mode == "damp":
            if self.odometry is not None:  # the legs' kinematics at the estimate, to correct it
                self.ctrl.update_model(state, tcp=False)
            cmd = damp_command(state.q)
            if arm.gripper_effort is not None:
                cmd.tau_ff[JAW] = arm.gripper_effort
            return cmd
        cmd_vel = self.arbiter.command(t) if self.mode == "walk" else np.zeros(3)
        if self.calibrating(t):  # the IMU learns its bias at rest: the gait waits
            cmd_vel = np.zeros(3)
        refs = WbcReferences(
            cmd_vel=cmd_vel,
            T_world_tcp=arm.T_world_tcp,
            tcp_twist=arm.tcp_twist,
            tcp_acceleration=arm.tcp_acceleration,
            arm_posture=arm.arm_posture,
            gripper_angle=arm.gripper_angle,
            gripper_effort=arm.gripper_effort,
        )
        cmd = self.ctrl.step(state, refs, dt)
        if self.odometry is not None and self.ctrl.gait.walking:
            self.odometry.moving()  # the calibration at rest is over
        timing = self.ctrl.last_timing
        self.qp_us = (timing.get("build", 0.0) + timing.get("solve", 0.0)) * 1e6
        return self.fallback.command(cmd, state, arm)

    def calibrating(self, t: int) -> bool:
        """Whether the odometry still calibrates at rest at t (within its timeout)."""
        odo = self.odometry
        if odo is None or not odo.calibrating:
            return False
        if t < self.calibrate_timeout_ns:
            return True
        odo.moving()
        self.say("odometry: no still second to calibrate the IMU in; going on uncalibrated")
        return False

    def end(self, t: int, msg: RobotState) -> None:
        """After the command went out: correct the odometry, observe the arm, record the
        base pose at t."""
        if self.odometry is not None:
            self.odometry.correct(self.ctrl.model, msg.foot_contacts)
        self.observe(msg)
        self.poses.add(t, self.ctrl.model.frames[robot.BASE_FRAME].H)

    # -- status ---------------------------------------------------------------------------

    def errors(self) -> tuple[float, float, float]:
        """Base error m, gripper_tcp error m and rad (0 unless a pose is tracked)."""
        return tracking_errors(self.ctrl, self.actions.tracking_pose and self.mode != "damp")

    def status(self, t: int, msg: RobotState, tick_us: float = 0.0) -> WbcStatus:
        """`wbc/status` at t (`tick_us`: the tick's compute, µs); updates the TCP wrench
        estimate from the state's torques."""
        m = self.ctrl.model
        wrench = self.wrench.update(
            m.h,
            m.v,
            np.asarray(as_numpy(msg.tau), dtype=float),
            m.frame_jacobian(TCP),  # computed here when no task needed it this tick
            m.frames[robot.BASE_FRAME].R,
        )
        base_err, tcp_m, tcp_rad = self.errors()
        return WbcStatus(
            stamp_ns=t,
            mode=self.mode,
            cmd_vel_source=self.arbiter.source,
            goals=self.actions.statuses(),
            base_error_m=base_err,
            gripper_error_m=tcp_m,
            gripper_error_rad=tcp_rad,
            qp_time_us=self.qp_us,
            qp_failures=self.fallback.qp_failures,
            contacts=msg.foot_contacts,
            gripper_angle=msg.gripper_angle,
            gripper_effort=msg.gripper_effort,
            held=self.actions.held,
            gripper_wrench=tuple(float(x) for x in wrench),  # type: ignore[arg-type]
            reason=self.reason,
            tick_us=tick_us,
            calibrating=self.odometry is not None and self.odometry.calibrating,
        )
