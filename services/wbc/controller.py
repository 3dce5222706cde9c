"""`WholeBodyController.step(state, references, dt) -> command`: one tick of the WBC.

Per tick: the state's base pose/twist and joints become pinocchio's (q, v); the model is
updated once; the trot gait advances (stance mask, swing targets); the task targets are
set (CoM xy, base height and orientation, swing feet, `gripper_tcp`, posture); the QP is
built and solved; the torques τ = M_a v̇ + h_a − J_c,aᵀ f go out as the feed-forward,
with PD targets at the state the QP's v̇ reaches one tick later
(q_des = q + v dt + ½ v̇ dt², v_des = v + v̇ dt), so the sim's own 1 kHz PD only corrects
what happens between ticks; the joints' damping and dry friction (which the rigid-body
model lacks) are fed forward from v_des. The jaw is position-controlled, or torque-limited when
closing on an object (`gripper_effort`), outside the QP's answer.

Values in and out mirror `common.messages.sim.RobotState` and `JointCommand` field by
field. The controller reads no clock: pass `clock` (e.g. `time.perf_counter`) to get the
per-phase timings in `last_timing` for monitoring.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from common import robot
from common.geometry import FloatArray, wrap_angle, yaw_of
from common.robot import joint_damping, joint_frictionloss
from services.wbc import constraints as cons
from services.wbc.gait import GaitParams, TrotGait
from services.wbc.model import RobotModel
from services.wbc.qp import (
    QpParams,
    QpSolution,
    QpSolver,
    build_qp,
    new_problem,
    structural_pattern,
)
from services.wbc.tasks import ComTask, FrameTask, PostureTask, Task
from services.wbc.values import ARM, JAW, WbcCommand, WbcGains, WbcReferences, WbcState

__all__ = [
    "WbcCommand",
    "WbcGains",
    "WbcReferences",
    "WbcState",
    "WholeBodyController",
]


def _rotation(quat_xyzw: FloatArray) -> FloatArray:
    """Rotation matrix of a unit quaternion x y z w (pinocchio's, ~20 times numpy's cost)."""
    return np.asarray(pin.Quaternion(np.asarray(quat_xyzw, dtype=float)).toRotationMatrix())


class WholeBodyController:
    """Stand and trot with the arm posture- or pose-controlled. One instance per robot."""

    def __init__(
        self,
        gains: WbcGains | None = None,
        qp_params: QpParams | None = None,
        gait_params: GaitParams | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.gains = g = gains or WbcGains()
        self.qp_params = qp_params or QpParams()
        self.model = RobotModel()
        self.gait = TrotGait(gait_params)
        self.clock = clock
        self.last_timing: dict[str, float] = {}
        self.com_task = ComTask(g.com_kp, g.com_kd, np.array([g.com_w, g.com_w, 0.0]))
        self.base_task = FrameTask(
            robot.BASE_FRAME, np.array(g.base_kp), np.array(g.base_kd), np.array(g.base_w)
        )
        self.foot_tasks = [FrameTask(f, g.swing_kp, g.swing_kd, 0.0) for f in robot.FOOT_FRAMES]
        self.tcp_task = FrameTask(robot.TCP_FRAME, g.tcp_kp, g.tcp_kd, 0.0)
        w_post = np.full(19, g.posture_w_legs)
        w_post[12:] = g.posture_w_arm
        self.posture_task = PostureTask(robot.POSTURES["stand"], g.posture_kp, g.posture_kd, w_post)
        self.tasks: list[Task] = [
            self.com_task,
            self.base_task,
            *self.foot_tasks,
            self.tcp_task,
            self.posture_task,
        ]
        self.f_ref = np.zeros(cons.NF)
        self.solver = self._make_solver()
        self.problem = new_problem(self.model.nv, self.qp_params)
        self.ref_xy = np.zeros(2)
        self.ref_yaw = 0.0
        self._initialised = False
        self.qp_failures = 0
        self._damping = joint_damping()  # N m s/rad, what the sim's joints dissipate
        self._friction = joint_frictionloss()  # N m
        self._last_tau = np.zeros(19)

    def _make_solver(self) -> QpSolver:
        """Set OSQP up on the structural pattern, from generic states in full stance."""
        rng = np.random.default_rng(0)
        problems = []
        for _ in range(3):
            q = robot.standing_q()
            q[7:] += rng.uniform(-0.3, 0.3, 19)
            q[3:7] = np.array([0.05, -0.04, 0.1, 1.0]) / np.linalg.norm([0.05, -0.04, 0.1, 1.0])
            self.model.update(q, rng.normal(0.0, 0.5, self.model.nv))
            problems.append(
                build_qp(self.model, self.tasks, np.ones(4), self.f_ref, self.qp_params)
            )
        return QpSolver(problems[0], structural_pattern(problems))

    def reset(self, state: WbcState) -> None:
        """Hold the current pose: references from the state, gait standing."""
        self.ref_yaw = yaw_of(_rotation(state.base_orientation_xyzw))
        self.gait = TrotGait(self.gait.params)
        self._initialised = True
        self._update_model(state)
        self.ref_xy = self.model.com[:2].copy()

    def _update_model(self, state: WbcState) -> FloatArray:
        R = _rotation(state.base_orientation_xyzw)
        q = np.concatenate([state.base_position_in_world, state.base_orientation_xyzw, state.q])
        v = np.concatenate(
            [
                R.T @ state.base_linear_velocity_in_world,
                state.base_angular_velocity_in_base,
                state.v,
            ]
        )
        self.model.update(q, v)
        return R

    def step(self, state: WbcState, refs: WbcReferences, dt: float) -> WbcCommand:
        """One control tick: the command to apply for the next `dt` seconds."""
        clock = self.clock
        t0 = clock() if clock else 0.0
        if not self._initialised:
            self.reset(state)
        R = self._update_model(state)
        m = self.model
        t1 = clock() if clock else 0.0
        yaw = yaw_of(R)
        feet = np.array([f.p for f in m.feet])
        self.gait.update(
            dt,
            refs.cmd_vel,
            m.frames[robot.BASE_FRAME].p[:2],
            yaw,
            m.vcom,
            float(m.com[2] - robot.FOOT_RADIUS_M),
            feet,
        )
        self._set_targets(refs, dt, feet)
        t_gait = clock() if clock else 0.0
        stance = self.gait.stance
        n_stance = max(float(stance.sum()), 1.0)
        self.f_ref[:] = 0.0
        self.f_ref[2::3] = stance * m.mass * 9.81 / n_stance
        problem = build_qp(m, self.tasks, stance, self.f_ref, self.qp_params, out=self.problem)
        t2 = clock() if clock else 0.0
        sol = self.solver.solve(problem)
        t3 = clock() if clock else 0.0
        cmd = self._command(state, refs, sol, dt)
        if clock:
            t4 = clock()
            self.last_timing = {
                "model": t1 - t0,
                "gait": t_gait - t1,
                "build": t2 - t_gait,
                "solve": t3 - t2,
                "output": t4 - t3,
                "total": t4 - t0,
            }
        return cmd

    def _set_targets(self, refs: WbcReferences, dt: float, feet: FloatArray) -> None:
        g, m, gait = self.gains, self.model, self.gait
        # Horizontal: CoM over the feet when standing, an integrated reference when walking.
        c, s = math.cos(self.ref_yaw), math.sin(self.ref_yaw)
        v_world = np.array([c * gait.cmd[0] - s * gait.cmd[1], s * gait.cmd[0] + c * gait.cmd[1]])
        if gait.walking:
            self.ref_xy += v_world * dt
            lead = self.ref_xy - m.com[:2]
            dist = math.hypot(lead[0], lead[1])
            if dist > g.tracking_slack_m:
                self.ref_xy = m.com[:2] + lead * (g.tracking_slack_m / dist)
        else:
            centre = feet[:, :2].mean(axis=0)
            step = centre - self.ref_xy
            np.clip(step, -0.2 * dt, 0.2 * dt, out=step)
            self.ref_xy += step
        self.ref_yaw += gait.cmd[2] * dt
        yaw_err = wrap_angle(self.ref_yaw - yaw_of(m.frames[robot.BASE_FRAME].R))
        if abs(yaw_err) > 0.3:
            self.ref_yaw -= math.copysign(abs(yaw_err) - 0.3, yaw_err)
        self.com_task.p_ref[:2] = self.ref_xy
        self.com_task.v_ref[:2] = v_world
        self.base_task.p_ref[2] = refs.base_height
        c, s = math.cos(self.ref_yaw), math.sin(self.ref_yaw)
        R_ref = self.base_task.R_ref  # yaw only: the trunk stays level
        R_ref[0, 0], R_ref[0, 1], R_ref[1, 0], R_ref[1, 1] = c, -s, s, c
        self.base_task.v_ref[5] = gait.cmd[2]
        for k, task in enumerate(self.foot_tasks):
            swing = gait.swing.get(k)
            if swing is None:
                task.weight[:] = 0.0
                continue
            task.weight[:3] = g.swing_w
            task.set_target(swing.p)
            task.v_ref[:3], task.a_ff[:3] = swing.v, swing.a
        self.posture_task.q_ref[ARM] = refs.arm_posture
        self.posture_task.q_ref[JAW] = refs.gripper_angle
        if refs.T_world_tcp is None:
            self.tcp_task.weight[:] = 0.0
            self.posture_task.weight[ARM] = g.posture_w_arm
        else:
            self.tcp_task.weight[:] = g.tcp_w
            self.posture_task.weight[ARM] = g.posture_w_arm_reaching
            self.tcp_task.set_target(refs.T_world_tcp[:3, 3], refs.T_world_tcp[:3, :3])
            self.tcp_task.v_ref[:] = 0.0 if refs.tcp_twist is None else refs.tcp_twist
            a_ff = refs.tcp_acceleration
            self.tcp_task.a_ff[:] = 0.0 if a_ff is None else a_ff

    def _command(
        self, state: WbcState, refs: WbcReferences, sol: QpSolution, dt: float
    ) -> WbcCommand:
        g, m = self.gains, self.model
        if sol.ok:
            tau = cons.joint_torques(m, sol.vdot, sol.f)
            self._last_tau = tau
        else:
            self.qp_failures += 1
            tau = self._last_tau
        qdd = sol.vdot[6:]
        q_des = state.q + state.v * dt + 0.5 * qdd * dt * dt
        v_des = state.v + qdd * dt
        kp = np.full(19, g.joint_kp)
        kd = np.full(19, g.joint_kd)
        # The model has no joint damping or dry friction; the sim's joints have both.
        tau = tau + self._damping * v_des + self._friction * np.tanh(v_des / g.friction_v)
        np.clip(tau, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS, out=tau)
        if refs.gripper_effort is not None:
            tau[JAW], kp[JAW], kd[JAW] = refs.gripper_effort, 0.0, g.jaw_kd
        else:
            tau[JAW], kp[JAW], kd[JAW] = 0.0, g.jaw_kp, g.jaw_kd
            q_des[JAW], v_des[JAW] = refs.gripper_angle, 0.0
        return WbcCommand(tau, q_des, v_des, kp, kd, sol.ok, sol.status, self.gait.stance.copy())
