"""The whole-body controller driving the MuJoCo robot in one process, no Zenoh: the
harness `dume bench wbc`, `dume trial pick` and the controller's unit tests build on.

Each 1 ms physics step reads the state through `services.sim.mjcf`'s maps, runs one
controller tick, applies τ = τ_ff + kp (q_des − q) + kd (v_des − v) clipped to the URDF
limits (as the sim will) and calls `mj_step`. Modes:

- stand: 30 s standing; base height error.
- trot: vx 0.5 m/s for 60 s with a 0.5 kg `spike_payload` body fixed at gripper_tcp.
- turn: trot in place at ωz 0.5 rad/s, then strafe at vy 0.2 m/s.
- grasp: the small world's bottle from its truth pose, the whole robot standing across the
  nearest table edge: reach a pregrasp, approach, close the jaw with limited torque, lift
  10 cm, shake ±5 cm sideways; held when the bottle stayed in the jaws by contact alone.
- seat: a cylinder grasped as in carry with its axis at given places along the jaws, and
  the jaw's angle once it holds (`services.mission.seat`'s figures: hall seed 10's can_3,
  `--world hall --seed 10 --artifact can_3`: -0.616, -0.690, -0.767, -0.861 rad with
  its axis 2, 1, 0 cm toward the tips and 1 cm deeper).
- carry: an artifact (`--world`, `--artifact`: cylinders) grasped as in grasp, the arm
  folded to `stow`, a knock on it (`--knock` N along world +y, 0.1 s: the shift eval's
  slip is 20 N), then a turn on the spot at `--wz`; held when it is still in the jaws.
  Hall seed 0's can_1, knocked at 20-80 N and grasped 0-5 cm above its middle, stays in
  the jaws through 6 s at 0.8 rad/s (as at 0): the turn's rate alone does not shake a
  knocked can out. `--walk S`: the turn is an about-face, then S s of walking at
  (`--vx`, 0, `--walk-wz`), the object's creep along the jaws (toward their tips) and
  the jaw's closing reported (`--vx 0`: turning on the spot, clear of the furniture).
  Walking creeps a cylinder out of the jaws' wedge: hall seed 10's can_3 (r 3.2 cm),
  turning on the spot at 0.5 rad/s for 60 s (`--world hall --seed 10 --artifact can_3
  --knock 0 --walk 60 --vx 0 --walk-wz 0.5`), crept 13 mm toward the tips and 7 mm
  down, the jaw closing 0.10 rad; in the shift it fell so after a 78 s carry (a search
  for the person, then a turn). Not a slip at the friction's limit: with a
  pad friction of 1.6 (1.2), an impratio of 1000 (100), MuJoCo's noslip pass, rolling
  friction, a carry effort of 10 N m (5) or a position hold on the jaw it crept as fast
  or fell sooner (a probe on the same can, 30-60 s walks).

The last line printed is a JSON object of figures (fell, distance, drift, base height and
attitude stats, controller tick p50/p99 in µs split by phase, real-time factor).
Usage: python -m bench.wbc_harness MODE [--seconds S] [--seed N] (carry: [--world W]
[--artifact ID] [--knock N] [--wz RATE] [--walk S --vx V --walk-wz RATE]; seat: [--world
W] [--artifact ID] [--deeper M,M,...])
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import msgspec
import mujoco
import numpy as np

from common import robot
from common.geometry import FloatArray, quat_wxyz_to_xyzw, rpy_of_quat_xyzw, yaw_of_quat_xyzw
from common.messages.world import RobotStart, WorldDescription
from services.sim import mjcf
from services.sim.scene import compile_scene
from services.sim.world import generate_world
from services.wbc.controller import WbcCommand, WbcReferences, WbcState, WholeBodyController
from services.wbc.gait import quintic
from services.wbc.reach import PoseSegment, pregrasp, side_grasp

PAYLOAD_BODY = "spike_payload"
Figures = dict[str, Any]  # JSON-ready numbers for the last line
FELL_HEIGHT_M = 0.3
FELL_TILT_RAD = math.radians(30.0)


def floor_spec(payload_kg: float = 0.0) -> mujoco.MjSpec:
    """The robot standing on a plane, optionally with a payload fixed at gripper_tcp."""
    spec = mjcf.robot_spec()
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[50, 50, 0.1])
    spec.worldbody.first_body().pos = [0.0, 0.0, robot.STAND_BASE_HEIGHT_M]
    if payload_kg > 0.0:
        add_payload(spec, payload_kg)
    return spec


def add_payload(spec: mujoco.MjSpec, mass_kg: float) -> None:
    """A non-colliding 0.5 kg-style point mass welded at gripper_tcp (spike only)."""
    body = spec.body("gripperStator").add_body(
        name=PAYLOAD_BODY, pos=list(robot.T_STATOR_TCP[:3, 3])
    )
    body.add_geom(
        name=PAYLOAD_BODY,
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[0.03, 0, 0],
        mass=mass_kg,
        contype=0,
        conaffinity=0,
    )


def read_state(model: mujoco.MjModel, data: mujoco.MjData, idx: mjcf.MjRobotIndices) -> WbcState:
    """The robot's state as `RobotState` carries it, from MuJoCo's qpos/qvel."""
    qpos, qvel = data.qpos[idx.qpos], data.qvel[idx.qvel]
    return WbcState(
        q=mjcf.joints_mj_to_pin(qpos[7:]),
        v=mjcf.joints_mj_to_pin(qvel[6:]),
        base_position_in_world=qpos[:3].copy(),
        base_orientation_xyzw=quat_wxyz_to_xyzw(qpos[3:7]),
        base_linear_velocity_in_world=qvel[:3].copy(),
        base_angular_velocity_in_base=qvel[3:6].copy(),
    )


def apply_command(
    data: mujoco.MjData, idx: mjcf.MjRobotIndices, state: WbcState, cmd: WbcCommand
) -> None:
    """τ = τ_ff + kp (q_des − q) + kd (v_des − v), clipped, into the actuators."""
    tau = cmd.tau_ff + cmd.kp * (cmd.q_des - state.q) + cmd.kd * (cmd.v_des - state.v)
    data.ctrl[idx.ctrl] = np.clip(tau, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS)


def set_initial_pose(model: mujoco.MjModel, data: mujoco.MjData, q: FloatArray) -> None:
    idx = mjcf.mj_indices(model)
    data.qpos[idx.qpos] = mjcf.q_pin_to_mj(q)
    mujoco.mj_forward(model, data)


@dataclass
class Log:
    """Per-tick figures the report summarises."""

    t: list[float] = field(default_factory=list)
    pos: list[FloatArray] = field(default_factory=list)
    rpy: list[FloatArray] = field(default_factory=list)
    timing: list[dict[str, float]] = field(default_factory=list)
    qp_fail: int = 0


RefsAt = Callable[[float, WbcState], WbcReferences]


def simulate(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    seconds: float,
    refs_at: RefsAt,
    on_start: Callable[[WholeBodyController], object] | None = None,
) -> tuple[Log, WholeBodyController, float]:
    """Run the loop; return the log, the controller and the wall time, s. `on_start` is
    handed the controller before the first tick (a test that disturbs its state)."""
    idx = mjcf.mj_indices(model)
    ctrl = WholeBodyController(clock=time.perf_counter)
    if on_start is not None:
        on_start(ctrl)
    log = Log()
    dt = model.opt.timestep
    n = round(seconds / dt)
    wall0 = time.perf_counter()
    for k in range(n):
        state = read_state(model, data, idx)
        cmd = ctrl.step(state, refs_at(k * dt, state), dt)
        apply_command(data, idx, state, cmd)
        mujoco.mj_step(model, data)
        log.t.append(k * dt)
        log.pos.append(state.base_position_in_world)
        log.rpy.append(rpy_of_quat_xyzw(state.base_orientation_xyzw))
        log.timing.append(ctrl.last_timing)
        if state.base_position_in_world[2] < FELL_HEIGHT_M:
            break
    log.qp_fail = ctrl.qp_failures
    return log, ctrl, time.perf_counter() - wall0


def summary(log: Log, wall_s: float, heading: FloatArray | None = None) -> Figures:
    pos, rpy = np.array(log.pos), np.array(log.rpy)
    sim_s = len(log.t) * mjcf.TIMESTEP_S
    tilt = np.max(np.abs(rpy[:, :2]))
    fell = bool(pos[:, 2].min() < FELL_HEIGHT_M or tilt > FELL_TILT_RAD)
    d = pos[-1, :2] - pos[0, :2]
    h = heading if heading is not None else np.array([1.0, 0.0])
    after = pos[len(pos) // 10 :, 2]  # height stats after the first 10 %
    out: Figures = {
        "fell": fell,
        "sim_s": round(sim_s, 3),
        "distance_m": round(float(d @ h), 3),
        "drift_m": round(float(abs(d @ np.array([-h[1], h[0]]))), 3),
        "yaw_rad": round(float(np.unwrap(rpy[:, 2])[-1] - rpy[0, 2]), 3),
        "height_mean_m": round(float(after.mean()), 4),
        "height_err_max_m": round(float(np.max(np.abs(after - robot.STAND_BASE_HEIGHT_M))), 4),
        "roll_pitch_max_deg": round(float(np.degrees(tilt)), 2),
        "qp_failures": log.qp_fail,
        "rtf": round(sim_s / wall_s, 3),
    }
    for key in ("total", "model", "gait", "build", "solve", "output"):
        us = np.array([t[key] for t in log.timing if t]) * 1e6
        out[f"tick_{key}_p50_us"] = round(float(np.percentile(us, 50)), 1)
        out[f"tick_{key}_p99_us"] = round(float(np.percentile(us, 99)), 1)
    return out


def run_walk(seconds: float, cmd: tuple[float, float, float], payload_kg: float) -> Figures:
    model = floor_spec(payload_kg).compile()
    data = mujoco.MjData(model)
    set_initial_pose(model, data, robot.standing_q())
    ramp = 0.5  # stand this long first

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        return WbcReferences(cmd_vel=np.array(cmd) if t > ramp else np.zeros(3))

    log, _, wall = simulate(model, data, seconds, refs_at)
    return summary(log, wall)


# --- grasp: the whole robot standing, the bottle's truth pose ----------------------------


@dataclass
class GraspPlan:
    """The standing pose facing the bottle and the TCP poses, from the world's truth."""

    q0: FloatArray  # robot standing q (26,)
    T_grasp: FloatArray  # gripper_tcp at the bottle's body centre (truth)
    approach: FloatArray  # (2,) horizontal approach direction in world
    table_top_m: float
    bottle_id: str


def grasp_plan(world: WorldDescription, artifact_id: str = "") -> GraspPlan:
    """Stand `D_OPT_M` back from the artifact (the world's first unless named) across the
    table edge nearest to it."""
    named = [a for a in world.artifacts if a.id == (artifact_id or a.id)]
    if not named:
        raise ValueError(f"no {artifact_id} here: {', '.join(a.id for a in world.artifacts)}")
    bottle_truth = named[0]
    table = next(o for o in world.obstacles if o.id == bottle_truth.surface_id)
    c, s = math.cos(table.yaw), math.sin(table.yaw)
    R = np.array([[c, -s], [s, c]])
    local = R.T @ (np.array(bottle_truth.position[:2]) - np.array(table.centre[:2]))
    hx, hy = table.half_size[:2]
    gaps = {(1.0, 0.0): hx - local[0], (-1.0, 0.0): hx + local[0]}
    gaps |= {(0.0, 1.0): hy - local[1], (0.0, -1.0): hy + local[1]}
    normal = R @ np.array(min(gaps, key=lambda k: gaps[k]))  # out of the table, world
    base_xy = np.array(bottle_truth.position[:2]) + normal * robot.D_OPT_M
    yaw = math.atan2(-normal[1], -normal[0])
    shape = bottle_truth.shape
    height = shape.height
    centre = np.array(bottle_truth.position) + np.array([0.0, 0.0, 0.375 * height])  # mid-body
    return GraspPlan(
        q0=robot.standing_q("stand", base_xy[0], base_xy[1], yaw),
        T_grasp=side_grasp(centre, -normal),
        approach=-normal,
        table_top_m=2 * table.half_size[2],
        bottle_id=bottle_truth.id,
    )


#: Phase durations, s, in order.
GRASP_PHASES = {
    "settle": 1.0, "ready": 1.5, "pregrasp": 2.0, "approach": 1.5,
    "close": 1.0, "lift": 1.5, "shake": 3.0, "hold": 1.5,
}  # fmt: skip
GRIP_EFFORT_NM = 4.0
GRIP_CARRY_NM = 5.0  # the stack's wbc.grip_effort_max_nm
SHAKE_M, SHAKE_HZ = 0.05, 1.5


class GraspScript:
    """Time-driven references: reach, approach, close with limited torque, lift, shake."""

    def __init__(self, plan: GraspPlan) -> None:
        self.plan = plan
        self.starts: dict[str, float] = {}
        t = 0.0
        for name, duration in GRASP_PHASES.items():
            self.starts[name] = t
            t += duration
        self.end = t
        self.T_pre = pregrasp(plan.T_grasp, 0.12, np.array([1.0, 0.0, 0.0]))
        self.T_lift = plan.T_grasp.copy()
        self.T_lift[2, 3] += 0.10
        self.segments: dict[str, PoseSegment] = {}

    def phase(self, t: float) -> str:
        return [n for n, t0 in self.starts.items() if t >= t0][-1]

    def __call__(self, t: float, state: WbcState, tcp_now: FloatArray) -> WbcReferences:
        name = self.phase(t)
        ready = robot.POSTURES["ready"][12:18].copy()
        if name == "settle":
            return WbcReferences()
        if name == "ready":  # joint space first: the TCP task then starts well conditioned
            return WbcReferences(arm_posture=ready, gripper_angle=robot.GRIPPER_OPEN)
        if name not in self.segments:  # each segment starts where the TCP target was
            start = {"pregrasp": tcp_now, "approach": self.T_pre, "lift": self.plan.T_grasp}
            goal = {"pregrasp": self.T_pre, "approach": self.plan.T_grasp, "lift": self.T_lift}
            if name in start:
                self.segments[name] = PoseSegment(start[name], goal[name], GRASP_PHASES[name])
        tau = t - self.starts[name]
        if name in self.segments:
            ref = self.segments[name].sample(tau)
            T, twist, acc = ref.T, ref.twist, ref.acceleration
        elif name == "close":
            T, twist, acc = self.plan.T_grasp, None, None
        else:
            T, twist, acc = self.T_lift.copy(), np.zeros(6), np.zeros(6)
            if name == "shake":
                side = np.array([-self.plan.approach[1], self.plan.approach[0], 0.0])
                w = 2 * math.pi * SHAKE_HZ
                T[:3, 3] += side * SHAKE_M * math.sin(w * tau)
                twist[:3] = side * SHAKE_M * w * math.cos(w * tau)
                acc[:3] = -side * SHAKE_M * w * w * math.sin(w * tau)
        closing = name in ("close", "lift", "shake", "hold")
        return WbcReferences(
            T_world_tcp=T,
            tcp_twist=twist,
            tcp_acceleration=acc,
            arm_posture=ready,
            gripper_angle=robot.GRIPPER_OPEN,
            gripper_effort=GRIP_EFFORT_NM if closing else None,
        )


def grasp_scene(world: WorldDescription, plan: GraspPlan) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The world with the robot standing at the plan's stance, ready to step."""
    start = RobotStart(float(plan.q0[0]), float(plan.q0[1]), yaw_of_quat_xyzw(plan.q0[3:7]))
    model = compile_scene(msgspec.structs.replace(world, robot_start=start))
    data = mujoco.MjData(model)
    set_initial_pose(model, data, plan.q0)
    return model, data


def run_grasp(seed: int) -> Figures:
    world = generate_world(seed, "small")
    plan = grasp_plan(world)
    model, data = grasp_scene(world, plan)
    script = GraspScript(plan)
    tcp_site = model.site(robot.TCP_FRAME).id
    bottle = model.body(plan.bottle_id).id
    rel: list[FloatArray] = []

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        T_tcp = np.eye(4)
        T_tcp[:3, :3] = data.site_xmat[tcp_site].reshape(3, 3)
        T_tcp[:3, 3] = data.site_xpos[tcp_site]
        if script.phase(t) in ("shake", "hold"):  # the bottle in the TCP frame (truth)
            rel.append(T_tcp[:3, :3].T @ (data.xpos[bottle] - T_tcp[:3, 3]))
        return script(t, state, T_tcp)

    log, _, wall = simulate(model, data, script.end, refs_at)
    out = summary(log, wall)
    tcp = data.site_xpos[tcp_site]
    bottle_truth_z = float(data.xpos[bottle][2])
    slip = np.array(rel)
    held = bool(
        bottle_truth_z > plan.table_top_m + 0.05
        and np.linalg.norm(data.xpos[bottle] - tcp) < 0.1
        and len(slip) > 0
        and np.ptp(slip, axis=0).max() < 0.02
    )
    out |= {
        "held": held,
        "bottle_truth_lift_m": round(bottle_truth_z - plan.table_top_m, 3),
        "bottle_slip_in_tcp_m": round(float(np.ptp(slip, axis=0).max()), 4) if len(slip) else None,
        "tcp_error_m": round(float(np.linalg.norm(tcp - script.T_lift[:3, 3])), 4),
        "gripper_angle_rad": round(float(log_gripper(model, data)), 3),
    }
    return out


#: carry: after the lift, the arm folds to `stow` (s), stands, the knock, a wait, the
#: turn on the spot, a stand; the turn's rate ramps at the navigator's ωz acceleration.
CARRY_PHASES = {"stow": 2.5, "steady": 1.0, "knock": 0.1, "wait": 1.0, "turn": 6.0, "stop": 2.0}
TURN_ACCEL = 1.5  # rad/s², navigation's controller a_max
WALK_ACCEL = 0.8  # m/s², navigation's controller a_max


def run_carry(
    seed: int,
    world_name: str,
    artifact: str,
    knock_n: float,
    wz: float,
    walk: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Figures:
    """Grasp (as `grasp`, no shake), fold to `stow` on a quintic, then a knock of `knock_n`
    N along world +y for 0.1 s on the object (the shift eval's slip), a second's stand, and
    a turn on the spot at `wz` rad/s; held when it is still in the jaws at the end. `walk`
    (seconds, vx m/s, ωz rad/s): the turn an about-face, then that walk (the module
    docstring); the object's creep along the jaws (the stator's x) and the jaw's closing
    over it are reported."""
    world = generate_world(seed, world_name)
    plan = grasp_plan(world, artifact)
    if next(a for a in world.artifacts if a.id == plan.bottle_id).object_class == "box":
        raise ValueError(f"{plan.bottle_id}: the side grasp here is a cylinder's")
    model, data = grasp_scene(world, plan)
    script = GraspScript(plan)
    grasp_end = script.starts["shake"]
    walk_s, walk_vx, walk_wz = walk
    phases = dict(CARRY_PHASES)
    if walk_s > 0.0:  # an about-face, the walk, then the stand
        stop = phases.pop("stop")
        phases |= {"turn": math.pi / abs(wz), "walk": walk_s, "stop": stop}
    starts, t = {}, grasp_end
    for name, duration in phases.items():
        starts[name] = t
        t += duration
    tcp_site = model.site(robot.TCP_FRAME).id
    body = model.body(plan.bottle_id).id
    stow = robot.POSTURES["stow"][12:18]
    q_lift: list[FloatArray] = []
    gap: dict[str, float] = {}
    knocked: list[FloatArray] = []  # the object's place as the knock began, then its sway
    walked: list[tuple[float, float]] = []  # the walk's (object along the jaws, jaw angle)

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        T_tcp = np.eye(4)
        T_tcp[:3, :3] = data.site_xmat[tcp_site].reshape(3, 3)
        T_tcp[:3, 3] = data.site_xpos[tcp_site]
        data.xfrc_applied[body] = 0.0
        if t < grasp_end:
            return script(t, state, T_tcp)
        phase = [n for n, t0 in starts.items() if t >= t0][-1]
        gap[phase] = max(gap.get(phase, 0.0), float(np.linalg.norm(data.xpos[body] - T_tcp[:3, 3])))
        if not q_lift:
            q_lift.append(state.q[12:18].copy())
        s, _, _ = quintic(min(1.0, (t - starts["stow"]) / CARRY_PHASES["stow"]))
        if phase == "knock":
            data.xfrc_applied[body, 1] = knock_n
        if phase in ("knock", "wait"):
            knocked.append(data.xpos[body].copy())
        w, vx = 0.0, 0.0
        if phase == "turn":
            w = min(abs(wz), TURN_ACCEL * (t - starts["turn"])) * math.copysign(1.0, wz)
        elif phase == "walk":
            tw = t - starts["walk"]
            vx, w = min(walk_vx, WALK_ACCEL * tw), min(abs(walk_wz), TURN_ACCEL * tw)
            w = math.copysign(w, walk_wz)
            along = T_tcp[:3, :3].T @ (data.xpos[body] - T_tcp[:3, 3])
            walked.append((float(along[0]), log_gripper(model, data)))
        elif phase == "stop" and not walked:
            w = max(0.0, abs(wz) - TURN_ACCEL * (t - starts["stop"])) * math.copysign(1.0, wz)
        return WbcReferences(
            cmd_vel=np.array([vx, 0.0, w]),
            arm_posture=q_lift[0] + s * (stow - q_lift[0]),
            gripper_angle=robot.GRIPPER_OPEN,
            gripper_effort=GRIP_CARRY_NM,
        )

    log, _, wall = simulate(model, data, t, refs_at)
    out = summary(log, wall)
    tcp = data.site_xpos[tcp_site]
    out |= {
        "artifact": plan.bottle_id,
        "knock_n": knock_n,
        "wz": wz,
        "held": bool(np.linalg.norm(data.xpos[body] - tcp) < 0.1),
        "object_tcp_gap_max_m": {k: round(v, 3) for k, v in gap.items()},
        "object_knock_sway_m": round(
            float(np.linalg.norm(np.array(knocked) - knocked[0], axis=1).max()), 3
        ),
        "gripper_angle_rad": round(float(log_gripper(model, data)), 3),
    }
    if walked:
        held_walk = [w for w in walked if abs(w[0]) < 0.05] or walked[:1]  # between the pads
        out |= {
            "walk_s": walk_s, "walk_vx": walk_vx, "walk_wz": walk_wz,
            "walk_creep_m": round(held_walk[-1][0] - walked[0][0], 4),
            "walk_jaw_closed_rad": round(held_walk[-1][1] - walked[0][1], 4),
            "walk_held_s": round(len(held_walk) * mjcf.TIMESTEP_S, 1),
        }  # fmt: skip
    return out


def run_seat(seed: int, world_name: str, artifact: str, deeper_m: list[float]) -> Figures:
    """A cylinder grasped as in `carry`, its axis each of `deeper_m` nearer the palm than
    the TCP (the grasp pose moved along the approach), and the jaw's angle once closed
    (the mean over 0.3 s into the lift): the sim's truth for `services.mission.seat`."""
    world = generate_world(seed, world_name)
    seats = [
        {"axis_along_jaws_m": -d, "jaw_rad": round(seat_once(world, artifact, d), 4)}
        for d in deeper_m
    ]
    return {"artifact": grasp_plan(world, artifact).bottle_id, "seats": seats}


def seat_once(world: WorldDescription, artifact: str, deeper_m: float) -> float:
    """The jaw's angle (rad) once it closed on `artifact` grasped `deeper_m` deeper."""
    plan = grasp_plan(world, artifact)
    T = plan.T_grasp.copy()
    T[:2, 3] += deeper_m * np.asarray(plan.approach)[:2]
    plan = replace(plan, T_grasp=T)
    model, data = grasp_scene(world, plan)
    script = GraspScript(plan)
    tcp_site = model.site(robot.TCP_FRAME).id
    jaw: list[float] = []

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        T_tcp = np.eye(4)
        T_tcp[:3, :3] = data.site_xmat[tcp_site].reshape(3, 3)
        T_tcp[:3, 3] = data.site_xpos[tcp_site]
        if t >= script.starts["lift"]:
            jaw.append(log_gripper(model, data))
        return script(t, state, T_tcp)

    simulate(model, data, script.starts["lift"] + 0.3, refs_at)
    return float(np.mean(jaw))


def log_gripper(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    return float(data.qpos[model.joint(robot.GRIPPER_JOINT).qposadr[0]])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "mode", choices=["stand", "trot", "turn", "strafe", "grasp", "carry", "seat"]
    )
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--vx", type=float, default=0.5)
    parser.add_argument("--wz", type=float, default=0.8)
    parser.add_argument("--knock", type=float, default=20.0, help="carry: N along world +y")
    parser.add_argument("--world", default="small", help="carry: small or hall")
    parser.add_argument("--artifact", default="", help="carry: its id (the world's first)")
    parser.add_argument("--walk", type=float, default=0.0, help="carry: s of walking after")
    parser.add_argument("--walk-wz", type=float, default=0.5, help="carry: the walk's rad/s")
    parser.add_argument("--deeper", default="-0.02,-0.01,0,0.01",
                        help="seat: m the grasp goes deeper, comma-separated")  # fmt: skip
    args = parser.parse_args()
    if args.mode == "stand":
        out = run_walk(args.seconds or 30.0, (0.0, 0.0, 0.0), 0.0)
    elif args.mode == "trot":
        out = run_walk(args.seconds or 60.0, (args.vx, 0.0, 0.0), 0.5)
    elif args.mode == "turn":
        out = run_walk(args.seconds or 20.0, (0.0, 0.0, 0.5), 0.0)
    elif args.mode == "strafe":
        out = run_walk(args.seconds or 20.0, (0.0, 0.2, 0.0), 0.0)
    elif args.mode == "seat":
        deeper = [float(v) for v in args.deeper.split(",")]
        out = run_seat(args.seed, args.world, args.artifact, deeper)
    elif args.mode == "carry":
        walk = (args.walk, args.vx if args.walk else 0.0, args.walk_wz)
        out = run_carry(args.seed, args.world, args.artifact, args.knock, args.wz, walk)
    else:
        out = run_grasp(args.seed)
    out["mode"] = args.mode
    print(json.dumps(out))


if __name__ == "__main__":
    main()
