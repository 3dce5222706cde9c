"""`WholeBodyController.step(state, references, dt) -> command`: one tick of the WBC.

Per tick: the state's base pose/twist and joints become pinocchio's (q, v); the model is
updated once; the trot gait advances (stance mask, swing targets); the task targets are
set (CoM xy, base height and orientation, swing feet, `gripper_tcp`, posture); the QP is
built and solved; the torques τ = M_a v̇ + h_a − J_c,aᵀ f go out as the feed-forward,
with PD targets at the state the QP's v̇ reaches one tick later
(q_des = q + v dt + ½ v̇ dt², v_des = v + v̇ dt), so the sim's own 1 kHz PD only corrects
what happens between ticks; the joints' damping and dry friction (which the rigid-body
model lacks) are fed forward from v_des. The jaw is position-controlled, or torque-limited when
closing on an object (`gripper_effort`), outside the QP's answer. The `gripper_tcp` task
adds integral action on its position (`tcp_ki`, bounded): a held object the model does
not know would otherwise sag the gripper by 1–3 cm. Only what the active tasks need is
computed: no `gripper_tcp` Jacobian or drift without a TCP target. While walking, the CoM
reference integrates the commanded velocity, leading the CoM by at most `tracking_slack_m`;
when the translation asked for stops, the lead keeps only its part along the CoM's motion
and within its stopping distance (braking at `stop_decel_mps2`), and the reference is
held there, so a stop is a stop even after a walk that was held back.

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
from common.config import GaitSettings
from common.geometry import FloatArray, wrap_angle, yaw_of
from common.robot import joint_damping, joint_frictionloss
from services.wbc import constraints as cons
from services.wbc.gait import STOP_THRESHOLD, TrotGait
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

_XYZ = slice(0, 3)

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
        gait: GaitSettings | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.gains = g = gains or WbcGains()
        self.qp_params = qp_params or QpParams()
        self.model = RobotModel()
        self.gait = TrotGait(gait or GaitSettings())
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
        #: No translation was asked last tick (the stop's re-anchoring, `_set_targets`).
        self._still = True
        self.ref_yaw = 0.0
        self._initialised = False
        self.qp_failures = 0
        self._damping = joint_damping()  # N m s/rad, what the sim's joints dissipate
        self._friction = joint_frictionloss()  # N m
        self._last_tau = np.zeros(19)
        self._q = np.zeros(self.model.nq)
        self._v = np.zeros(self.model.nv)
        self._kp = np.full(19, g.joint_kp)
        self._kd = np.full(19, g.joint_kd)
        self._tcp_integral = np.zeros(3)  # ∫ (p_ref − p) dt of gripper_tcp, m s
        self._neg_torque_limits = -robot.TORQUE_LIMITS

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
        self.gait = TrotGait(self.gait.limits)
        self._initialised = True
        self.update_model(state, tcp=True)
        self.ref_xy = self.model.com[:2].copy()
        self._tcp_integral[:] = 0.0

    def update_model(self, state: WbcState, tcp: bool) -> FloatArray:
        """The model at the state (`tcp`: with the gripper's Jacobian); R of the base."""
        R = _rotation(state.base_orientation_xyzw)
        q, v = self._q, self._v
        q[:3] = state.base_position_in_world
        q[3:7] = state.base_orientation_xyzw
        q[7:] = state.q
        np.dot(state.base_linear_velocity_in_world, R, out=v[:3])  # Rᵀ v
        v[3:6] = state.base_angular_velocity_in_base
        v[6:] = state.v
        self.model.update(q, v, tcp=tcp)
        return R

    def step(self, state: WbcState, refs: WbcReferences, dt: float) -> WbcCommand:
        """One control tick: the command to apply for the next `dt` seconds."""
        clock = self.clock
        t0 = clock() if clock else 0.0
        if not self._initialised:
            self.reset(state)
        R = self.update_model(state, tcp=refs.T_world_tcp is not None)
        m = self.model
        t1 = clock() if clock else 0.0
        feet = m.feet_p
        self.gait.update(
            dt,
            refs.cmd_vel,
            m.frames[robot.BASE_FRAME].p[:2],
            math.atan2(R[1, 0], R[0, 0]),
            m.vcom,
            float(m.com[2]) - robot.FOOT_RADIUS_M,
            feet,
        )
        self._set_targets(refs, dt)
        t_gait = clock() if clock else 0.0
        stance = self.gait.stance
        n_stance = max(float(stance.sum()), 1.0)
        np.multiply(stance, m.mass * 9.81 / n_stance, out=self.f_ref[2::3])
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

    def _set_targets(self, refs: WbcReferences, dt: float) -> None:
        g, m, gait = self.gains, self.model, self.gait
        # Horizontal: CoM over the feet when standing, an integrated reference when walking.
        vx, vy, wz = gait.cmd.tolist()
        c, s = math.cos(self.ref_yaw), math.sin(self.ref_yaw)
        v_world = (c * vx - s * vy, s * vx + c * vy)
        com_x, com_y = m.com[0], m.com[1]
        rx, ry = self.ref_xy
        still = math.hypot(refs.cmd_vel[0], refs.cmd_vel[1]) < STOP_THRESHOLD
        if gait.walking:
            rx, ry = rx + v_world[0] * dt, ry + v_world[1] * dt
            lx, ly = rx - com_x, ry - com_y
            dist = math.hypot(lx, ly)
            if still and not self._still:
                # The translation asked for just stopped: of the lead, only its part along
                # the CoM's motion and within its stopping distance at `stop_decel_mps2`
                # is kept, and the reference held there. A lead left by a walk that was
                # held back (a pallet against the hips) was chased at 0.2-0.45 m/s after
                # navigation had stopped the base for a person.
                speed = math.hypot(m.vcom[0], m.vcom[1])
                ux, uy = (m.vcom[0] / speed, m.vcom[1] / speed) if speed > 1e-3 else (0.0, 0.0)
                ahead = min(max(lx * ux + ly * uy, 0.0), speed * speed / (2 * g.stop_decel_mps2))
                rx, ry = com_x + ahead * ux, com_y + ahead * uy
            elif dist > g.tracking_slack_m:
                k = g.tracking_slack_m / dist
                rx, ry = com_x + lx * k, com_y + ly * k
        else:
            feet = m.feet_p
            cx = 0.25 * (feet[0, 0] + feet[1, 0] + feet[2, 0] + feet[3, 0])
            cy = 0.25 * (feet[0, 1] + feet[1, 1] + feet[2, 1] + feet[3, 1])
            lim = 0.2 * dt
            rx += min(max(cx - rx, -lim), lim)
            ry += min(max(cy - ry, -lim), lim)
        self.ref_xy[0], self.ref_xy[1] = rx, ry
        self._still = still
        self.ref_yaw += wz * dt
        R_base = m.frames[robot.BASE_FRAME].R
        yaw_err = wrap_angle(self.ref_yaw - math.atan2(R_base[1, 0], R_base[0, 0]))
        if abs(yaw_err) > 0.3:
            self.ref_yaw -= math.copysign(abs(yaw_err) - 0.3, yaw_err)
        com = self.com_task
        com.p_ref[0], com.p_ref[1] = rx, ry
        com.v_ref[0], com.v_ref[1] = v_world
        self.base_task.p_ref[2] = refs.base_height
        c, s = math.cos(self.ref_yaw), math.sin(self.ref_yaw)
        R_ref = self.base_task.R_ref  # yaw only: the trunk stays level
        R_ref[0, 0], R_ref[0, 1], R_ref[1, 0], R_ref[1, 1] = c, -s, s, c
        self.base_task.v_ref[5] = wz
        swing = gait.swing
        for k, task in enumerate(self.foot_tasks):
            target = swing.get(k)
            if target is None:
                if task.active:
                    task.set_weight(0.0)
                continue
            if not task.active:
                task.set_weight(g.swing_w, _XYZ)
            task.p_ref[:] = target.p
            task.v_ref[:3], task.a_ff[:3] = target.v, target.a
        posture = self.posture_task
        posture.q_ref[ARM] = refs.arm_posture
        posture.q_ref[JAW] = refs.gripper_angle
        tcp = self.tcp_task
        if refs.T_world_tcp is None:
            if tcp.active:
                tcp.set_weight(0.0)
                posture.set_weight(g.posture_w_arm, ARM)
            self._tcp_integral[:] = 0.0
            return
        if not tcp.active:
            tcp.set_weight(g.tcp_w)
            posture.set_weight(g.posture_w_arm_reaching, ARM)
        T = refs.T_world_tcp
        tcp.set_target(T[:3, 3], T[:3, :3])
        if refs.tcp_twist is None:
            tcp.v_ref[:] = 0.0
        else:
            tcp.v_ref[:] = refs.tcp_twist
        a_ff = tcp.a_ff
        if refs.tcp_acceleration is None:
            a_ff[:] = 0.0
        else:
            a_ff[:] = refs.tcp_acceleration
        # Integral action on the position: a payload the model does not know (a held
        # bottle) sags the arm; the integral finds the extra force, bounded against windup.
        if g.tcp_ki > 0.0:
            e = self._tcp_integral
            e += (tcp.p_ref - m.frames[robot.TCP_FRAME].p) * dt
            np.clip(e, -g.tcp_integral_max, g.tcp_integral_max, out=e)
            a_ff[:3] += g.tcp_ki * e

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
        v_des = qdd * dt
        v_des += state.v
        q_des = v_des + state.v  # q + (v + v_des) dt / 2 = q + v dt + ½ v̇ dt²
        q_des *= 0.5 * dt
        q_des += state.q
        kp, kd = self._kp.copy(), self._kd.copy()
        # The model has no joint damping or dry friction; the sim's joints have both.
        tau = tau + self._damping * v_des
        tau += self._friction * np.tanh(v_des * (1.0 / g.friction_v))
        np.minimum(tau, robot.TORQUE_LIMITS, out=tau)
        np.maximum(tau, self._neg_torque_limits, out=tau)
        if refs.gripper_effort is not None:
            tau[JAW], kp[JAW], kd[JAW] = refs.gripper_effort, 0.0, g.jaw_kd
        else:
            tau[JAW], kp[JAW], kd[JAW] = 0.0, g.jaw_kp, g.jaw_kd
            q_des[JAW], v_des[JAW] = refs.gripper_angle, 0.0
        return WbcCommand(tau, q_des, v_des, kp, kd, sol.ok, sol.status, self.gait.stance.copy())
