"""The robot in MuJoCo, and the maps between MuJoCo's state and pinocchio's.

`robot_spec()` loads `urdf_text()` (the URDF pinocchio also loads) with static bodies kept
unfused (`fusestatic="false"`), so every URDF link is a MuJoCo body of the same name: the
SRDF's disabled pairs become `<exclude>`s by link name and the feet, stator and mover keep
their frames. Welded bodies share a weld group, inside which MuJoCo never collides, and
`filterparent` drops parent-child pairs, as pinocchio's pair list does (`common.robot`).
The root is a free joint `root`; each of the 19 joints gets a `motor` named after it, in
`JOINT_NAMES` order, whose ctrlrange is the URDF effort limit (MuJoCo clips the torque).

World: build the world into a fresh `robot_spec()` (add the floor and objects to its
worldbody), or `set_sim_options(world)` then `world.attach(robot_spec(), prefix=...,
frame=...)` (attach keeps the parent's options and warns when they differ); `mj_indices`
finds the robot's qpos/qvel/ctrl in either, by name. The feet and jaw pads have
`priority` 1, so their friction and solver parameters hold against world geoms left at
priority 0. The gripper collides as boxes (group 3, hidden) and renders as its STL meshes
(group 1, no contact, no mass).

MuJoCo state vs pinocchio's: MuJoCo orders the legs FR, FL, RR, RL and its free-joint
quaternion is wxyz, its qvel is [linear velocity in world, angular velocity in the base
frame]; pinocchio's q has xyzw and v is [linear, angular] both in the base frame.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt

from common.geometry import (
    FloatArray,
    matrix_to_quat_xyzw,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_matrix,
    quat_xyzw_to_wxyz,
)
from common.robot_description import (
    CAMERA_MOUNTS,
    FOOT_FRAMES,
    GRIPPER_BOXES,
    IMU_FRAME,
    JOINT_NAMES,
    LIDAR_MOUNT,
    LIDAR_REAR_MOUNT,
    MOVER_LINK,
    ROOT_JOINT,
    STATOR_LINK,
    T_STATOR_TCP,
    TCP_FRAME,
    gripper_stl_path,
    joint_armature,
    joint_damping,
    joint_frictionloss,
    srdf_disabled_pairs,
    urdf_joints,
    urdf_text,
)

TIMESTEP_S = 0.001  # 1 kHz
INTEGRATOR = mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # joint damping integrated implicitly
# Elliptic cones with friction 100x stiffer than the normal. With MuJoCo's defaults a held
# bottle creeps out of the jaws at ~1 cm/s; at 10x the single revolute jaw's wedge (its pads
# meet at ~35 deg on a 6 cm bottle) still squeezed a carried bottle out, the jaw closing
# 0.1 rad in 20 s of walking; at 100x it holds still (0.003 rad) and the gait is unchanged
# (walk and push trials identical to the millimetre). No noslip pass: it also acts on the
# joints' dry friction, and the arm then sticks short of its postures.
CONE = mujoco.mjtCone.mjCONE_ELLIPTIC
IMPRATIO = 100.0
_COMPILER = '<mujoco><compiler discardvisual="true" fusestatic="false"/></mujoco>'
FOOT_FRICTION = (0.9, 0.02, 0.001)  # sliding, torsional, rolling; condim 3 uses sliding
# Jaw pads: grippy rubber, torsional friction (condim 4) so a held bottle does not spin,
# and a stiff contact (time constant 4 ms at 1 ms steps) so it does not sink and slide.
PAD_FRICTION = (1.2, 0.02, 0.0001)
PAD_SOLREF = (0.004, 1.0)
PAD_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
_MJ_CAMERA_FROM_OPTICAL = np.diag([1.0, -1.0, -1.0])  # MuJoCo cameras look down -z, y up
GRIPPER_COLLISION_GROUP = 3  # not rendered by default: the STL visuals show the gripper
VISUAL_GROUP = 1


def _wxyz(R: npt.ArrayLike) -> list[float]:
    return [float(x) for x in quat_xyzw_to_wxyz(matrix_to_quat_xyzw(R))]


def robot_spec() -> mujoco.MjSpec:
    """A fresh MjSpec of the robot alone (no floor), its free joint `root` at the origin.

    Geoms are named as pinocchio's (`<link>_<k>`, plus the `GRIPPER_BOXES`), sites
    `gripper_tcp` and the feet mark pinocchio's frames, cameras are `CAMERA_MOUNTS`.
    """
    urdf = urdf_text()
    end = urdf.index(">", urdf.index("<robot ")) + 1  # the compiler goes inside <robot>
    spec = mujoco.MjSpec.from_string(urdf[:end] + _COMPILER + urdf[end:])
    spec.compiler.discardvisual = False  # the URDF's .dae visuals are gone; keep ours
    spec.modelname = "dume_b1_z1"
    set_sim_options(spec)
    spec.worldbody.first_body().add_freejoint(name=ROOT_JOINT)

    counts: dict[str, int] = {}
    for geom in spec.geoms:
        body = geom.parent.name
        geom.name = f"{body}_{counts.get(body, 0)}"
        counts[body] = counts.get(body, 0) + 1
    for foot in FOOT_FRAMES:
        geom = spec.geom(f"{foot}_0")
        geom.condim, geom.priority, geom.friction = 3, 1, FOOT_FRICTION
        spec.body(foot).add_site(name=foot, size=[0.01, 0, 0])
    _add_gripper(spec)
    _add_cameras(spec)
    _add_sensors(spec)

    for name, armature, damping, friction in zip(
        JOINT_NAMES, joint_armature(), joint_damping(), joint_frictionloss(), strict=True
    ):
        joint = spec.joint(name)
        joint.armature, joint.frictionloss = armature, friction
        joint.damping = [damping, 0.0, 0.0]  # MuJoCo 4: the linear term, then higher orders
        effort = urdf_joints()[name].effort
        spec.add_actuator(
            name=name,
            target=name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            ctrllimited=True,
            ctrlrange=[-effort, effort],
        )
    for link1, link2 in srdf_disabled_pairs():
        spec.add_exclude(bodyname1=link1, bodyname2=link2)
    return spec


def set_sim_options(spec: mujoco.MjSpec) -> None:
    """Set the physics options the robot is tuned for (timestep, integrator, cone, impratio).

    `robot_spec()` has them; a world that attaches the robot must set them itself.
    """
    spec.option.timestep = TIMESTEP_S
    spec.option.integrator = INTEGRATOR
    spec.option.cone = CONE
    spec.option.impratio = IMPRATIO


def _add_gripper(spec: mujoco.MjSpec) -> None:
    for box in GRIPPER_BOXES:
        geom = spec.body(box.link).add_geom(
            name=box.name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=list(box.center),
            size=list(box.half_size),
            group=GRIPPER_COLLISION_GROUP,
            rgba=[0.9, 0.5, 0.1, 0.4],
        )
        if box.is_jaw_pad:
            geom.condim, geom.priority, geom.friction = 4, 1, PAD_FRICTION
            geom.solref, geom.solimp = PAD_SOLREF, PAD_SOLIMP
    for link in (STATOR_LINK, MOVER_LINK):  # the real jaws, for cameras only
        spec.add_mesh(name=f"{link}_visual", file=gripper_stl_path(link).as_posix())
        spec.body(link).add_geom(
            name=f"{link}_visual",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"{link}_visual",
            contype=0,
            conaffinity=0,
            group=VISUAL_GROUP,
            mass=0.0,
            density=0.0,
            rgba=[0.56, 0.63, 0.75, 1.0],
        )
    spec.body(STATOR_LINK).add_site(
        name=TCP_FRAME,
        pos=list(T_STATOR_TCP[:3, 3]),
        quat=_wxyz(T_STATOR_TCP[:3, :3]),
        size=[0.005, 0, 0],
    )


#: The sensors' sites: a group the renderer does not draw (it draws sites of groups 0-2).
SENSOR_SITE_GROUP = 4
#: The IMU's MuJoCo sensors, in `sensordata`'s order: angular velocity (rad/s) and
#: specific force (m/s²), both in the IMU's frame.
IMU_SENSORS = (
    ("imu_gyro", mujoco.mjtSensor.mjSENS_GYRO),
    ("imu_accel", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
)


def imu_sensor_addresses(model: mujoco.MjModel) -> tuple[slice, slice]:
    """Where the gyro's and the accelerometer's readings lie in `MjData.sensordata`."""
    out = []
    for name, _ in IMU_SENSORS:
        sensor = model.sensor(name)
        adr, dim = int(sensor.adr[0]), int(sensor.dim[0])
        out.append(slice(adr, adr + dim))
    return out[0], out[1]


def _add_sensors(spec: mujoco.MjSpec) -> None:
    """The IMU (MuJoCo's gyro and accelerometer at site `IMU_FRAME`, read as the step's
    first stage computes them, noise added by `services.sim.sensors`) and the lidars'
    sites, front and rear (their rays are cast by `sensors.Lidar`)."""
    spec.body(IMU_FRAME).add_site(name=IMU_FRAME, size=[0.01, 0, 0], group=SENSOR_SITE_GROUP)
    site = mujoco.mjtObj.mjOBJ_SITE
    for name, kind in IMU_SENSORS:
        spec.add_sensor(name=name, type=kind, objtype=site, objname=IMU_FRAME)
    for mount in (LIDAR_MOUNT, LIDAR_REAR_MOUNT):
        T = mount.T_parent_lidar
        spec.body(mount.parent_frame).add_site(
            name=mount.name,
            pos=list(T[:3, 3]),
            quat=_wxyz(T[:3, :3]),
            size=[0.02, 0, 0],
            group=SENSOR_SITE_GROUP,  # not drawn: the cameras must not see it
        )


def _add_cameras(spec: mujoco.MjSpec) -> None:
    for mount in CAMERA_MOUNTS.values():
        R = mount.T_parent_camera[:3, :3] @ _MJ_CAMERA_FROM_OPTICAL
        spec.body(mount.parent_frame).add_camera(
            name=mount.name,
            pos=list(mount.T_parent_camera[:3, 3]),
            quat=_wxyz(R),
            fovy=mount.fovy_deg,
            resolution=[mount.width, mount.height],
        )


# --- state maps --------------------------------------------------------------------------


@dataclass(frozen=True)
class MjRobotIndices:
    """Where the robot lives in a compiled model (alone or attached into a world).

    qpos (26,), qvel (25,): addresses of the robot's free joint then its joints in
    MuJoCo's order (`mj_joint_names()`), i.e. what `q_mj_to_pin` and `v_mj_to_pin` take.
    ctrl (19,): actuator ids in `JOINT_NAMES` order: `data.ctrl[ctrl] = tau`.
    """

    qpos: npt.NDArray[np.intp]
    qvel: npt.NDArray[np.intp]
    ctrl: npt.NDArray[np.intp]


def mj_indices(model: mujoco.MjModel, prefix: str = "") -> MjRobotIndices:
    """The robot's state and actuator addresses in `model` (names prefixed by `prefix`)."""
    root = model.joint(prefix + ROOT_JOINT)
    qpos = list(range(int(root.qposadr[0]), int(root.qposadr[0]) + 7))
    qvel = list(range(int(root.dofadr[0]), int(root.dofadr[0]) + 6))
    for name in mj_joint_names():
        joint = model.joint(prefix + name)
        qpos.append(int(joint.qposadr[0]))
        qvel.append(int(joint.dofadr[0]))
    ctrl = [model.actuator(prefix + name).id for name in JOINT_NAMES]
    return MjRobotIndices(np.array(qpos), np.array(qvel), np.array(ctrl))


@functools.cache
def mj_joint_names() -> tuple[str, ...]:
    """The 19 joints in MuJoCo's model order (legs FR, FL, RR, RL, then the arm)."""
    model = robot_spec().compile()
    names = [model.joint(i).name for i in range(model.njnt)]
    return tuple(n for n in names if n != ROOT_JOINT)


@functools.cache
def _perm() -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    mj = mj_joint_names()
    pin_from_mj = np.array([mj.index(n) for n in JOINT_NAMES])
    mj_from_pin = np.array([JOINT_NAMES.index(n) for n in mj])
    return pin_from_mj, mj_from_pin


def joints_mj_to_pin(x: npt.ArrayLike) -> FloatArray:
    """A per-joint vector (19,) in MuJoCo's joint order → `JOINT_NAMES` order."""
    return np.asarray(x, dtype=float)[_perm()[0]]


def joints_pin_to_mj(x: npt.ArrayLike) -> FloatArray:
    """A per-joint vector (19,) in `JOINT_NAMES` order → MuJoCo's joint order."""
    return np.asarray(x, dtype=float)[_perm()[1]]


def q_mj_to_pin(qpos: npt.ArrayLike) -> FloatArray:
    """Robot qpos (26,: xyz, quat wxyz, joints MuJoCo order) → pinocchio q (xyzw, pin order)."""
    qpos = np.asarray(qpos, dtype=float)
    return np.concatenate([qpos[:3], quat_wxyz_to_xyzw(qpos[3:7]), joints_mj_to_pin(qpos[7:])])


def q_pin_to_mj(q: npt.ArrayLike) -> FloatArray:
    """Pinocchio q (26,) → robot qpos (26,) in MuJoCo's layout."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[:3], quat_xyzw_to_wxyz(q[3:7]), joints_pin_to_mj(q[7:])])


def v_mj_to_pin(qvel: npt.ArrayLike, qpos: npt.ArrayLike) -> FloatArray:
    """Robot qvel (25,: v world, omega base, joints) → pinocchio v (v base, omega base, joints)."""
    qvel = np.asarray(qvel, dtype=float)
    R = quat_xyzw_to_matrix(quat_wxyz_to_xyzw(np.asarray(qpos, dtype=float)[3:7]))
    return np.concatenate([R.T @ qvel[:3], qvel[3:6], joints_mj_to_pin(qvel[6:])])


def v_pin_to_mj(v: npt.ArrayLike, q: npt.ArrayLike) -> FloatArray:
    """Pinocchio v (25,) → robot qvel (25,) in MuJoCo's layout."""
    v = np.asarray(v, dtype=float)
    R = quat_xyzw_to_matrix(np.asarray(q, dtype=float)[3:7])
    return np.concatenate([R @ v[:3], v[3:6], joints_pin_to_mj(v[6:])])
