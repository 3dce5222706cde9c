"""The simulator's core, with no transport: the world's physics on a 1 kHz tick.

`SimCore(world, ...)` compiles the scene, stands the robot in `stand` at the world's start
(feet on the floor, no self-contact) and then, each tick, takes the newest joint command,
steps the physics one millisecond and reports what happened:

    state = core.robot_state(core.tick)          # publish; the controller answers it
    core.command(tau_ff, q_des, v_des, kp, kd, state.stamp_ns)   # CommandError if bad
    events = core.step()                          # t -> t + 1 ms; world events of the step

The PD law runs inside MuJoCo at the physics rate (`services.sim.drive`), a command holds
until the next one, and the watchdog holds the joints when commands stop. People turn
and walk (`people`), take what is held out to them (`handover`), and contacts become events
(`events`). With kinematic locomotion the base follows `set_cmd_vel` at the standing
height, level, while the legs hold `stand` and the arm still obeys commands; the feet are
made frictionless (condim 1) so they glide instead of dragging the held legs (with
friction a turn in place bends a hip by 0.17 rad), and foot contacts mean little there.
`push(force, duration)` applies an external force on the base (tests and evaluation: a
disturbance the controller must survive; `services.sim.push`).
The state carries what the robot's sensors measure (`services.sim.sensors`): joints and
feet as the encoders and force sensors read them, and the IMU, sampled after every step
(the bias walks whether or not anyone reads it); `lidar.scan(data)` casts the scan
(`lidar_rear` the rear scanner's).
Time is exact: `time_ns = tick * 1_000_000`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from common import robot
from common.config import SensorSettings
from common.geometry import FloatArray, make_T, quat_wxyz_to_xyzw, quat_xyzw_to_matrix
from common.messages import Array
from common.messages.sim import (
    ArtifactPose,
    Locomotion,
    Odom,
    RobotState,
    StateTruth,
    WorldEvent,
)
from common.messages.world import WorldDescription
from services.sim import mjcf, scene
from services.sim.drive import JAW, N_JOINTS, CommandError, JointDrive, joint_addresses, validate
from services.sim.events import ContactMonitor, DropMonitor
from services.sim.handover import Handover
from services.sim.people import People, RobotNear
from services.sim.push import PushError, PushQueue
from services.sim.sensors import Imu, JointSensors, Lidar, rng_for

TICK_NS = 1_000_000
#: An artifact taken away is parked this far beyond the hall's wall (m); one placed is
#: set this far above its support (m), to settle on it without starting in contact.
PARK_M = 20.0
PLACE_LIFT_M = 0.002
__all__ = ["TICK_NS", "CommandError", "PushError", "SimCore"]


class SimCore:
    """The world, the robot and its drives; stepped by `step`, read by `robot_state`."""

    def __init__(
        self,
        world: WorldDescription,
        *,
        locomotion: Locomotion = "dynamic",
        watchdog_ms: float = 20.0,
        walking_people: bool = False,
        bystanders: bool = False,
        sensors: SensorSettings | None = None,
    ) -> None:
        if locomotion not in ("dynamic", "kinematic"):
            raise ValueError(f"locomotion {locomotion!r} is not 'dynamic' or 'kinematic'")
        if watchdog_ms <= 0:
            raise ValueError(f"watchdog_ms must be positive, got {watchdog_ms}")
        self.world = world
        self.locomotion: Locomotion = locomotion
        self.model = scene.compile_scene(world)
        if round(self.model.opt.timestep * 1e9) != TICK_NS:
            raise ValueError(f"the scene's timestep {self.model.opt.timestep} s is not 1 ms")
        self.data = mujoco.MjData(self.model)
        self.dt = self.model.opt.timestep
        self.tick = 0
        idx = mjcf.mj_indices(self.model)
        self._base_q = np.asarray(idx.qpos[:7], dtype=np.intp)
        self._base_v = np.asarray(idx.qvel[:6], dtype=np.intp)
        self._base_xy = slice(int(idx.qpos[0]), int(idx.qpos[0]) + 2)
        self._q = joint_addresses(idx.qpos)
        self._v = joint_addresses(idx.qvel)
        self._robot_qpos = np.asarray(idx.qpos, dtype=np.intp)
        self._robot_qvel = np.asarray(idx.qvel, dtype=np.intp)
        self.drive = JointDrive(
            self.model, idx, round(watchdog_ms * 1e6), legs_held=locomotion == "kinematic"
        )
        self.people = People(self.model, world.people, walking_people, bystanders)
        self.handover = Handover(self.model, world)
        self.contacts = ContactMonitor(self.model, world)
        self.drops = DropMonitor(self.model, self.contacts.artifact_ids)
        self._artifact_q = [int(self.model.joint(a).qposadr[0]) for a in self.drops.ids]
        self._cmd_vel = (0.0, 0.0, 0.0)
        self.pushes = PushQueue(int(self.model.dof_bodyid[idx.qvel[0]]), self.dt)
        #: Knocks on artifacts (`push(..., target=artifact)`), a queue per artifact body.
        self.knocks: dict[str, PushQueue] = {}
        self._artifact_v = [int(self.model.joint(a).dofadr[0]) for a in self.drops.ids]
        if locomotion == "kinematic":
            for foot in robot.FOOT_FRAMES:
                self.model.geom_condim[self.model.geom(f"{foot}_0").id] = 1
        s = sensors or SensorSettings()
        self.imu = Imu(s.imu, self.dt, rng_for(world.seed, "imu"))
        self.joint_sensors = JointSensors(s.joints, rng_for(world.seed, "joints"))
        self.lidar = Lidar(self.model, s.lidar, rng_for(world.seed, "lidar"))
        #: The trunk's rear scanner (None when `sim.sensors.lidar.rear` is off).
        self.lidar_rear = (
            Lidar(self.model, s.lidar, rng_for(world.seed, "lidar_rear"), robot.LIDAR_REAR_MOUNT)
            if s.lidar.rear
            else None
        )
        self._imu_adr = mjcf.imu_sensor_addresses(self.model)
        self._measured: _Measured | None = None
        start = world.robot_start
        self._pose = (start.x, start.y, start.yaw)  # the kinematic base: x, y, yaw
        self.reset_robot(start.x, start.y, start.yaw)

    # -- inputs -----------------------------------------------------------------------------

    @property
    def time_ns(self) -> int:
        """Sim time of the current state, ns (exact)."""
        return self.tick * TICK_NS

    def command(
        self,
        tau_ff: ArrayLike,
        q_des: ArrayLike,
        v_des: ArrayLike,
        kp: ArrayLike,
        kd: ArrayLike,
        stamp_ns: int,
    ) -> None:
        """Drive the joints (19-vectors, `JOINT_NAMES` order) by τ = τ_ff + kp (q_des − q) +
        kd (v_des − v), clipped to the URDF limits, from the next step until replaced.

        Raises CommandError (wrong shape, NaN/inf, negative gain, stamp later than now);
        the previous command then stays in force.
        """
        arrays = {"tau_ff": tau_ff, "q_des": q_des, "v_des": v_des, "kp": kp, "kd": kd}
        cmd = validate(arrays, stamp_ns, self.time_ns)
        self.drive.command(cmd, int(stamp_ns), self.time_ns)

    def set_cmd_vel(self, vx: float, vy: float, wz: float) -> None:
        """The kinematic base's twist in `base_yaw` (m/s, m/s, rad/s), until replaced."""
        if self.locomotion != "kinematic":
            raise RuntimeError("set_cmd_vel drives the base only with kinematic locomotion")
        if not all(math.isfinite(x) for x in (vx, vy, wz)):
            raise CommandError([f"cmd_vel ({vx}, {vy}, {wz}) is not finite"])
        self._cmd_vel = (float(vx), float(vy), float(wz))

    def push(self, force_in_world: ArrayLike, duration_s: float, target: str = "base") -> int:
        """Push the base (or the artifact `target`: a knock) with `force_in_world` (3,) N
        at its centre of mass for `duration_s` from the next step on (200 N for 0.1 s =
        20 N·s); the number of steps it lasts.

        Raises PushError for a non-finite force, a duration outside (0, 10] s or a target
        that is neither the base nor an artifact of the world.
        """
        if target == "base":
            return self.pushes.add(force_in_world, duration_s)
        if target not in self.drops.ids:
            raise PushError(f"no artifact {target!r} to push; the world has {list(self.drops.ids)}")
        queue = self.knocks.get(target)
        if queue is None:
            queue = self.knocks[target] = PushQueue(self.model.body(target).id, self.dt)
        return queue.add(force_in_world, duration_s)

    def place_artifact(
        self, artifact_id: str, position: tuple[float, float, float] | None, yaw: float
    ) -> tuple[float, float, float]:
        """Somebody moves an artifact (a person who holds it lets go): its base onto
        `position` (m, world: the top of what it stands on), upright at `yaw`, at rest;
        None: away, parked beyond the hall's walls (in a row, out of every camera's
        sight). Where its base now is.

        Raises KeyError for an unknown artifact, ValueError for a non-finite position.
        """
        if artifact_id not in self.drops.ids:
            raise KeyError(f"no artifact {artifact_id!r}; the world has {list(self.drops.ids)}")
        k = self.drops.ids.index(artifact_id)
        if position is None:
            (_, y0), (x1, _) = self.world.hall.min_xy, self.world.hall.max_xy
            position = (x1 + PARK_M + 0.5 * k, y0, 0.0)
        if not all(math.isfinite(v) for v in (*position, yaw)):
            raise ValueError(f"an artifact's place must be finite, got {position}, yaw {yaw}")
        (x0, y0), (x1, y1) = self.world.hall.min_xy, self.world.hall.max_xy
        inside = x0 - PARK_M <= position[0] <= x1 + PARK_M + 0.5 * len(self.drops.ids)
        if not (inside and y0 - PARK_M <= position[1] <= y1 + PARK_M and 0.0 <= position[2] <= 3.0):
            raise ValueError(
                f"an artifact's place must be on the hall's floor or a support (z 0-3 m), "
                f"got {tuple(round(v, 3) for v in position)}"
            )
        self.handover.let_go(self.model, self.data, artifact_id)  # a person who held it
        adr, dof = self._artifact_q[k], self._artifact_v[k]
        x, y, z = (float(v) for v in position)
        self.data.qpos[adr : adr + 7] = (x, y, z + PLACE_LIFT_M, math.cos(0.5 * yaw), 0.0, 0.0,
                                         math.sin(0.5 * yaw))  # fmt: skip
        self.data.qvel[dof : dof + 6] = 0.0
        self.drops.forget(k)  # settling onto its new support is no drop
        mujoco.mj_forward(self.model, self.data)
        return x, y, z

    def artifact_poses(self) -> list[ArtifactPose]:
        """Every artifact's body origin (world, m) and uprightness (the cosine of its tilt)
        now (truth)."""
        out = []
        for k, artifact_id in enumerate(self.drops.ids):
            adr = self._artifact_q[k]
            x, y, z, _w, qx, qy, _qz = (float(v) for v in self.data.qpos[adr : adr + 7])
            upright = min(1.0, max(-1.0, 1.0 - 2.0 * (qx * qx + qy * qy)))
            out.append(ArtifactPose(id=artifact_id, position_in_world=(x, y, z), upright=upright))
        return out

    def place_movable(
        self, movable_id: str, position: tuple[float, float] | None, yaw: float
    ) -> tuple[float, float]:
        """Somebody leaves a movable (`WorldDescription.movables`: a trolley) standing at
        `position` (m, world, on the hall's floor) turned to `yaw`; None: parked again
        beyond the walls, where it started. Where its centre now is. Nothing checks what it
        lands on: the caller chooses free floor (`world.aisle_spot`).

        Raises KeyError for an unknown movable, ValueError for a place off the floor.
        """
        movable = next((m for m in self.world.movables if m.id == movable_id), None)
        if movable is None:
            have = [m.id for m in self.world.movables]
            raise KeyError(f"no movable {movable_id!r}; the world has {have}")
        if position is None:
            position, yaw = (movable.centre[0], movable.centre[1]), movable.yaw
        (x0, y0), (x1, y1) = self.world.hall.min_xy, self.world.hall.max_xy
        parked = position == (movable.centre[0], movable.centre[1])
        if not all(math.isfinite(v) for v in (*position, yaw)) or not (
            parked or (x0 <= position[0] <= x1 and y0 <= position[1] <= y1)
        ):
            raise ValueError(
                f"a movable's place must be on the hall's floor, got {position}, yaw {yaw}"
            )
        mocap = int(self.model.body_mocapid[self.model.body(movable_id).id])
        x, y = float(position[0]), float(position[1])
        self.data.mocap_pos[mocap] = (x, y, movable.centre[2])
        self.data.mocap_quat[mocap] = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
        mujoco.mj_forward(self.model, self.data)
        return x, y

    def reset_robot(self, x: float, y: float, yaw: float, posture: str = "stand") -> None:
        """Stand the robot still at (x, y, yaw) in `posture` (start-up and tests only)."""
        self.data.qpos[self._robot_qpos] = mjcf.q_pin_to_mj(robot.standing_q(posture, x, y, yaw))
        self.data.qvel[self._robot_qvel] = 0.0
        self._pose = (x, y, yaw)
        mujoco.mj_forward(self.model, self.data)
        self.contacts.update(self.data, self.time_ns)  # the feet's forces for the first state
        self._sense()

    # -- the tick ---------------------------------------------------------------------------

    def step(self) -> list[WorldEvent]:
        """One 1 ms physics step; the world events it produced (stamped at the new time)."""
        data = self.data
        self.drive.before_step(data, self.time_ns)
        self.drive.write(data)
        self.pushes.apply(data)
        for queue in self.knocks.values():
            queue.apply(data)
        self.people.update(data, self._robot_near(), self.dt)
        mujoco.mj_step(self.model, data)
        self.tick += 1
        if self.locomotion == "kinematic":
            self._move_base()
        stamp = self.time_ns
        events: list[WorldEvent] = []
        events.extend(self.contacts.update(data, stamp))
        found = self.contacts.contacts
        events.extend(self.handover.update(self.model, data, found, self.dt, stamp))
        events.extend(self.drops.update(data, found, self.handover.held, stamp))
        self._sense()
        return events

    def _robot_near(self) -> RobotNear:
        """The robot as people see it (its heading and what it carries only matter to
        bystanders: not computed for the others)."""
        x, y = self.data.qpos[self._base_xy].tolist()
        if not self.people.bystanders:
            return RobotNear(x, y)
        qw, qx, qy, qz = self.data.qpos[self._base_q[3:7]].tolist()
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        c = self.contacts.contacts
        carrying = not bool((c.artifact_on_world | c.artifact_asleep | self.handover.held).all())
        return RobotNear(x, y, yaw, carrying)

    def _sense(self) -> None:
        """Sample the IMU, the encoders and the feet for the state now (every step: the
        IMU's bias walks whether or not anyone reads it)."""
        data, adr = self.data, self._imu_adr
        gyro, accel = self.imu.read(data.sensordata[adr[0]], data.sensordata[adr[1]])
        q, v = self.joint_sensors.joints(data.qpos[self._q], data.qvel[self._v])
        forces, contacts = self.joint_sensors.feet(self.contacts.contacts.foot_force)
        self._measured = _Measured(q, v, forces, contacts, gyro, accel)

    def _move_base(self) -> None:
        """Advance the kinematic base by one step of cmd_vel; level, at standing height."""
        vx, vy, wz = self._cmd_vel
        x, y, yaw = self._pose
        mid = yaw + 0.5 * wz * self.dt
        c, s = math.cos(mid), math.sin(mid)
        x, y, yaw = (
            x + (c * vx - s * vy) * self.dt,
            y + (s * vx + c * vy) * self.dt,
            yaw + wz * self.dt,
        )
        self._pose = (x, y, math.remainder(yaw, math.tau))
        self.data.qpos[self._base_q] = (
            x,
            y,
            robot.STAND_BASE_HEIGHT_M,
            math.cos(0.5 * yaw),
            0.0,
            0.0,
            math.sin(0.5 * yaw),
        )
        c, s = math.cos(yaw), math.sin(yaw)
        self.data.qvel[self._base_v] = (c * vx - s * vy, s * vx + c * vy, 0.0, 0.0, 0.0, wz)

    # -- outputs ----------------------------------------------------------------------------

    def robot_state(self, tick: int | None = None) -> RobotState:
        """The state at the current time (tick defaults to the current one)."""
        if tick is not None and tick != self.tick:
            raise ValueError(f"state of tick {tick} asked at tick {self.tick}")
        data, m = self.data, self._measured
        assert m is not None  # sensed at every reset and step
        tau = self.drive.applied(data)
        fl, fr, rl, rr = m.foot_force.tolist()
        return RobotState(
            stamp_ns=self.time_ns,
            tick=self.tick,
            q=_joints(m.q),
            v=_joints(m.v),
            tau=_joints(tau),
            foot_contacts=m.contacts,
            foot_forces=(fl, fr, rl, rr),
            imu_angular_velocity=_vec3(m.gyro),
            imu_specific_force=_vec3(m.accel),
            gripper_angle=float(m.q[JAW]),
            gripper_effort=float(tau[JAW]),
            watchdog=self.drive.watchdog,
            watchdog_reason=self.drive.reason,
            locomotion=self.locomotion,
        )

    def odom(self) -> Odom:
        """The base and gripper at the current time (the slow consumers' view)."""
        data = self.data
        base_q, base_v = data.qpos[self._base_q], data.qvel[self._base_v]
        return Odom(
            stamp_ns=self.time_ns,
            base_position_in_world=tuple(base_q[:3].tolist()),
            base_orientation_xyzw=_xyzw(base_q),
            base_linear_velocity_in_world=tuple(base_v[:3].tolist()),
            base_angular_velocity_in_base=tuple(base_v[3:].tolist()),
            gripper_angle=float(data.qpos[self._q[JAW]]),
            gripper_effort=float(self.data.actuator_force[self.drive.act[JAW]]),
            watchdog=self.drive.watchdog,
            locomotion=self.locomotion,
        )

    def state_truth(self) -> StateTruth:
        """The base as MuJoCo's free joint has it now (truth: for evaluation)."""
        data = self.data
        base_q, base_v = data.qpos[self._base_q], data.qvel[self._base_v]
        return StateTruth(
            stamp_ns=self.time_ns,
            base_position_in_world=_vec3(base_q[:3]),
            base_orientation_xyzw=_xyzw(base_q),
            base_linear_velocity_in_world=_vec3(base_v[:3]),
            base_angular_velocity_in_base=_vec3(base_v[3:]),
        )

    def T_world_base(self) -> FloatArray:
        """The base in the world (4x4) at the current time."""
        base_q = self.data.qpos[self._base_q]
        return make_T(quat_xyzw_to_matrix(quat_wxyz_to_xyzw(base_q[3:7])), base_q[:3])

    def truth_positions(self) -> dict[str, tuple[float, float, float]]:
        """Artifact body origins and people's floor points in the world, m (sim truth)."""
        out = {a.id: a.position_in_world for a in self.artifact_poses()}
        for pid in self.people.ids:
            x, y, _ = self.people.pose(pid)
            out[pid] = (x, y, 0.0)
        return out


@dataclass(frozen=True)
class _Measured:
    """The sensors' sample for the current state (`services.sim.sensors`)."""

    q: FloatArray
    v: FloatArray
    foot_force: FloatArray
    contacts: tuple[bool, bool, bool, bool]
    gyro: FloatArray
    accel: FloatArray


def _vec3(x: FloatArray) -> tuple[float, float, float]:
    a, b, c = x.tolist()
    return a, b, c


def _joints(x: FloatArray) -> Array:
    """A fresh float64 (19,) vector on the wire (what `to_wire` does, without its checks)."""
    return Array("float64", (N_JOINTS,), x.astype("<f8", copy=False).tobytes())


def _xyzw(base_q: FloatArray) -> tuple[float, float, float, float]:
    w, x, y, z = base_q[3:7].tolist()
    return x, y, z, w
