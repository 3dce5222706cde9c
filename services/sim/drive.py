"""The robot's joint drives: the commanded PD law, run by MuJoCo itself, and the watchdog.

Each of the 19 motors becomes a joint servo at start-up: force = ctrl − kp q − kd q̇ with
ctrl = τ_ff + kp q_des + kd v_des, clipped to the URDF effort limits (`forcerange`; the
control itself is unclipped). So τ = τ_ff + kp (q_des − q) + kd (v_des − v) is evaluated
inside every `mj_step` at the physics rate, and `implicitfast` integrates the kd term
implicitly (stable at any kd). A command sets kp, kd and ctrl once; nothing runs per step.

The watchdog: when no command came for `watchdog_ns` of sim time, the drives latch the
joint positions and hold them with `WATCHDOG_KP`/`WATCHDOG_KD` (the jaw keeps its last
torque, so a grasp holds); a new command releases it. With kinematic locomotion the legs
always hold the `stand` posture and only the arm and jaw follow commands.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from common import robot
from services.sim import mjcf
from services.sim.standing import STAND_KD, STAND_KP, WATCHDOG_KD, WATCHDOG_KP

N_JOINTS = len(robot.JOINT_NAMES)
JAW = robot.JOINT_NAMES.index(robot.GRIPPER_JOINT)
LEGS = np.arange(len(robot.LEG_JOINTS))
FIELDS = ("tau_ff", "q_des", "v_des", "kp", "kd")


class CommandError(ValueError):
    """A joint command that cannot be applied; `problems` lists what was wrong with it."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        super().__init__("; ".join(problems))


def validate(
    arrays: dict[str, ArrayLike], stamp_ns: int, now_ns: int
) -> dict[str, NDArray[np.float64]]:
    """The command's five vectors as float64 (19,); CommandError lists every problem."""
    try:  # the common case, checked at once
        stacked = np.array([arrays[name] for name in FIELDS], dtype=np.float64)
        ok = (
            stacked.shape == (len(FIELDS), N_JOINTS)
            and -math.inf < stacked.min() <= stacked.max() < math.inf  # False for NaN
            and stacked[3:].min() >= 0.0
            and isinstance(stamp_ns, int | np.integer)
            and 0 <= stamp_ns <= now_ns
        )
    except (TypeError, ValueError):
        ok = False
    if ok:
        return dict(zip(FIELDS, stacked, strict=True))
    raise CommandError(_problems(arrays, stamp_ns, now_ns))


def _problems(arrays: dict[str, ArrayLike], stamp_ns: int, now_ns: int) -> list[str]:
    """Everything wrong with a command, one sentence each."""
    problems: list[str] = []
    for name in FIELDS:
        try:
            value = np.asarray(arrays[name], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            problems.append(f"{name} is not numeric: {exc}")
            continue
        if value.shape != (N_JOINTS,):
            problems.append(f"{name} has shape {value.shape}, expected ({N_JOINTS},)")
            continue
        bad = ~np.isfinite(value)
        if bad.any():
            names = [robot.JOINT_NAMES[i] for i in np.flatnonzero(bad)]
            problems.append(f"{name} is not finite at {names}")
            continue
        if name in ("kp", "kd") and (value < 0).any():
            names = [robot.JOINT_NAMES[i] for i in np.flatnonzero(value < 0)]
            problems.append(f"{name} is negative at {names}; gains must be >= 0")
    if not isinstance(stamp_ns, int | np.integer) or stamp_ns < 0:
        problems.append(f"stamp_ns {stamp_ns!r} is not a non-negative integer")
    elif stamp_ns > now_ns:
        problems.append(f"stamp_ns {stamp_ns} is later than the sim time {now_ns}")
    return problems


def joint_addresses(robot_addresses: NDArray[np.intp]) -> NDArray[np.intp]:
    """The 19 joints' addresses in `JOINT_NAMES` order from `MjRobotIndices.qpos`/`.qvel`."""
    mj = mjcf.mj_joint_names()
    order = [mj.index(name) for name in robot.JOINT_NAMES]
    start = len(robot_addresses) - N_JOINTS
    return np.asarray(robot_addresses[start:], dtype=np.intp)[order]


class JointDrive:
    """The 19 motors of the robot in `model` as PD servos (see the module docstring)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        indices: mjcf.MjRobotIndices,
        watchdog_ns: int,
        legs_held: bool,
    ) -> None:
        self.model = model
        self.act = np.asarray(indices.ctrl, dtype=np.intp)  # JOINT_NAMES order
        first = int(self.act[0])  # a basic slice where the ids run in order: cheaper writes
        contiguous = np.array_equal(self.act, np.arange(first, first + N_JOINTS))
        self._act: slice | NDArray[np.intp] = (
            slice(first, first + N_JOINTS) if contiguous else self.act
        )
        self.qpos = joint_addresses(indices.qpos)
        self.watchdog_ns = watchdog_ns
        self.legs_held = legs_held
        self.watchdog = False
        self.reason = ""
        self.last_command_ns = 0  # sim time the last command arrived
        self.last_stamp_ns = -1  # its stamp
        self._ctrl = np.zeros(N_JOINTS)
        self._dirty = True
        limits = model.actuator_ctrlrange[self.act].copy()
        model.actuator_ctrllimited[self.act] = 0
        model.actuator_forcelimited[self.act] = 1
        model.actuator_forcerange[self.act] = limits
        model.actuator_biastype[self.act] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_gainprm[self.act, 0] = 1.0
        self._set(np.zeros(N_JOINTS), np.zeros(N_JOINTS), np.zeros(N_JOINTS))

    def command(self, cmd: dict[str, NDArray[np.float64]], stamp_ns: int, now_ns: int) -> None:
        """Apply a validated command (`validate`) from now on; release the watchdog."""
        kp, kd = cmd["kp"], cmd["kd"]
        self._set(kp, kd, cmd["tau_ff"] + kp * cmd["q_des"] + kd * cmd["v_des"])
        self.last_command_ns, self.last_stamp_ns = now_ns, stamp_ns
        if self.watchdog:
            self.watchdog, self.reason = False, ""

    def before_step(self, data: mujoco.MjData, now_ns: int) -> None:
        """Engage the watchdog when the last command is `watchdog_ns` old (call every step)."""
        if self.watchdog or now_ns - self.last_command_ns < self.watchdog_ns:
            return
        q = data.qpos[self.qpos]
        ctrl = WATCHDOG_KP * q
        ctrl[JAW] += data.actuator_force[self.act[JAW]]
        self._set(WATCHDOG_KP, WATCHDOG_KD, ctrl)
        self.write(data)
        self.watchdog = True
        self.reason = f"no command for {self.watchdog_ns / 1e6:g} ms"

    def applied(self, data: mujoco.MjData) -> NDArray[np.float64]:
        """The torques (19,) N m applied in the last step, after clipping."""
        return np.array(data.actuator_force[self._act])

    def _set(self, kp: ArrayLike, kd: ArrayLike, ctrl: ArrayLike) -> None:
        bias = self.model.actuator_biasprm[self._act]
        bias[:, 1] = kp
        bias[:, 2] = kd
        bias[:, 1:3] *= -1.0
        self._ctrl[:] = ctrl
        if self.legs_held:  # kinematic locomotion: the legs keep the stand posture
            bias[LEGS, 1], bias[LEGS, 2] = -STAND_KP[LEGS], -STAND_KD[LEGS]
            self._ctrl[LEGS] = STAND_KP[LEGS] * robot.POSTURES["stand"][LEGS]
        if not isinstance(self._act, slice):
            self.model.actuator_biasprm[self._act] = bias
        self._dirty = True

    def write(self, data: mujoco.MjData) -> None:
        """Put the drives' controls into `data.ctrl` when they changed (before each step)."""
        if self._dirty:
            data.ctrl[self._act] = self._ctrl
            self._dirty = False
