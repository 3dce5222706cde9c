"""dume's robot: the Unitree B1 with a Z1 arm from example-robot-data — the one place for
its conventions.

- Joints: `JOINT_NAMES` is pinocchio's model order: legs FL, FR, RL, RR (hip, thigh,
  calf), arm joint1..joint6, then the jaw `jointGripper` (0 closed, negative open). Every
  19-vector in dume (q, v, tau, limits, postures) uses it. MuJoCo orders the legs FR, FL,
  RR, RL: the simulator crosses over with `services.sim.mjcf` (`q_mj_to_pin`,
  `v_mj_to_pin` and back, `mj_indices(model).ctrl`).
- State: pinocchio q (26) = [base position in world, base quaternion xyzw, joints];
  v (25) = [base linear, angular velocity, both in the base frame, joint velocities].
- Frames: `base` (= trunk), feet `FL_foot`.. (sphere centres), `gripper_tcp` (x approach,
  z towards the moving jaw, y along the jaw pivot: see `T_STATOR_TCP`) and the cameras.
  Camera frames are OpenCV optical frames (z forward, x right, y down); MuJoCo's cameras
  look down their -z with y up, and `services.sim.mjcf.robot_spec()` turns them.
- Standing, reaching and standoff numbers are computed below from the kinematics, each
  with how it was derived.

The facts both models share (files, names, gripper boxes, camera mounts) are in
`robot_description` and re-exported here, so import from here; the MuJoCo model and its
state maps are the simulator's (`services.sim.mjcf`).

Importing this module is cheap: it loads numpy and the description, not pinocchio, coal
or MuJoCo, and computes nothing from the kinematics. The names, postures, the grasp and
approach settings (`GRASP_*`, `APPROACH_MARGIN_M`, `PERSON_REACH_M`, `THETA_OPT_RAD`) are
plain values. The joint limits, `FOOT_RADIUS_M`, `STAND_BASE_HEIGHT_M`, `ARM_REACH_M`,
`D_OPT_M`, `STANDOFF_DISTANCE_M`, `HANDOVER_DISTANCE_M` and `FOOTPRINT*` need the pinocchio
model, and the reach ones a scan of the arm's joint grid (~0.2 s): each is computed on its
first access (`robot.D_OPT_M` or `from common.robot import D_OPT_M`, which is an access
too), then kept as a plain module attribute. The functions (`load_pinocchio`,
`standing_q`, `arm_plane`, `tcp_reach_gap`, `Footprint.stowed`) load pinocchio when called.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from common.geometry import FloatArray, rot_z
from common.robot_description import (
    ARM_JOINTS,
    BASE_FRAME,
    CAMERA_MOUNTS,
    FOOT_FRAMES,
    GRIPPER_BOXES,
    GRIPPER_CLOSED,
    GRIPPER_JOINT,
    GRIPPER_OPEN,
    GRIPPER_WIDE,
    IMU_FRAME,
    JAW_GEOMS,
    JOINT_NAMES,
    LEG_JOINTS,
    LEG_NAMES,
    LIDAR_MOUNT,
    LIDAR_REAR_MOUNT,
    STATOR_LINK,
    T_STATOR_TCP,
    TCP_FRAME,
    CameraMount,
    LidarMount,
    joint_armature,
    joint_damping,
    joint_frictionloss,
    srdf_path,
    urdf_text,
)

if TYPE_CHECKING:
    import pinocchio as pin

__all__ = [  # the description's names, re-exported, and this module's
    "APPROACH_MARGIN_M",
    "ARM_JOINTS",
    "ARM_REACH_M",
    "BASE_FRAME",
    "CAMERA_MOUNTS",
    "D_OPT_M",
    "FOOTPRINT",
    "FOOTPRINT_BOUNDS",
    "FOOT_FRAMES",
    "FOOT_RADIUS_M",
    "GRASP_HEIGHTS_M",
    "GRASP_PITCH_RAD",
    "GRIPPER_CLOSED",
    "GRIPPER_JOINT",
    "GRIPPER_OPEN",
    "GRIPPER_WIDE",
    "HANDOVER_DISTANCE_M",
    "IMU_FRAME",
    "JAW_GEOMS",
    "JOINT_NAMES",
    "LEG_JOINTS",
    "LEG_NAMES",
    "LIDAR_MOUNT",
    "LIDAR_REAR_MOUNT",
    "PERSON_REACH_M",
    "POSITION_LOWER",
    "POSITION_UPPER",
    "POSTURES",
    "STANDOFF_DISTANCE_M",
    "STAND_BASE_HEIGHT_M",
    "TCP_FRAME",
    "THETA_OPT_RAD",
    "TORQUE_LIMITS",
    "T_STATOR_TCP",
    "VELOCITY_LIMITS",
    "CameraMount",
    "Footprint",
    "LidarMount",
    "arm_plane",
    "intrinsics",
    "joint_damping",
    "joint_frictionloss",
    "load_pinocchio",
    "posture_front_m",
    "standing_q",
    "tcp_reach_gap",
]

if TYPE_CHECKING:
    # Computed on first access (see `_LAZY` at the end, and the module docstring); declared
    # here so that type checkers see them.
    POSITION_LOWER: FloatArray  # rad
    POSITION_UPPER: FloatArray  # rad
    VELOCITY_LIMITS: FloatArray  # rad/s
    TORQUE_LIMITS: FloatArray  # N m, MuJoCo clips to these
    FOOT_RADIUS_M: float
    # Base height with the feet spheres resting on z = 0 in the `stand` legs.
    STAND_BASE_HEIGHT_M: float
    # See `_reach_and_standoff`.
    ARM_REACH_M: float
    D_OPT_M: float
    STANDOFF_DISTANCE_M: float  # base origin to object, nav goal: D_OPT_M + APPROACH_MARGIN_M
    # Base origin to the person: the TCP's reach in `handover` plus the person's own reach.
    HANDOVER_DISTANCE_M: float
    # (x_min, x_max, y_min, y_max) of the robot with the arm stowed: see `_footprint`.
    FOOTPRINT_BOUNDS: tuple[float, float, float, float]
    # Half-extents (x, y) of a base-centred rectangle holding the robot with the arm stowed.
    FOOTPRINT: tuple[float, float]


@functools.cache
def load_pinocchio() -> tuple[pin.Model, pin.GeometryModel]:
    """The robot in pinocchio (free-flyer root, nq 26, nv 25) and its collision model.

    Shared and cached: treat both as read-only (`pin.Model(model)` copies). The model has
    dume's joint armature (as MuJoCo does) and the frames `gripper_tcp`, `camera_head`,
    `camera_wrist`. The collision model has the gripper boxes MuJoCo uses and the pairs
    MuJoCo checks: all, minus the SRDF's disabled ones and minus parent-child bodies.
    """
    import coal
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf_text(), pin.JointModelFreeFlyer())
    armature = model.armature.copy()
    armature[6:] = joint_armature()
    model.armature = armature
    stator = model.getFrameId(STATOR_LINK, pin.FrameType.BODY)
    _add_frame(model, TCP_FRAME, stator, T_STATOR_TCP)
    for mount in CAMERA_MOUNTS.values():
        parent = model.getFrameId(mount.parent_frame, pin.FrameType.BODY)
        _add_frame(model, mount.name, parent, mount.T_parent_camera)

    geom = pin.buildGeomFromUrdfString(model, urdf_text(), pin.GeometryType.COLLISION)
    for box in GRIPPER_BOXES:
        frame = model.frames[model.getFrameId(box.link, pin.FrameType.BODY)]
        shape = coal.Box(*(2.0 * np.array(box.half_size)))
        placement = frame.placement * pin.SE3(np.eye(3), np.array(box.center))
        geom.addGeometryObject(
            pin.GeometryObject(
                box.name,
                frame.parentJoint,
                model.getFrameId(box.link, pin.FrameType.BODY),
                placement,
                shape,
            )
        )
    geom.addAllCollisionPairs()
    pin.removeCollisionPairs(model, geom, str(srdf_path()))
    for pair in list(geom.collisionPairs):
        j1 = geom.geometryObjects[pair.first].parentJoint
        j2 = geom.geometryObjects[pair.second].parentJoint
        if j1 == j2 or model.parents[j1] == j2 or model.parents[j2] == j1:
            geom.removeCollisionPair(pair)
    return model, geom


def _add_frame(model: pin.Model, name: str, parent_frame: int, T: FloatArray) -> None:
    import pinocchio as pin

    parent = model.frames[parent_frame]
    placement = parent.placement * pin.SE3(T[:3, :3], T[:3, 3])
    model.addFrame(
        pin.Frame(name, parent.parentJoint, parent_frame, placement, pin.FrameType.OP_FRAME)
    )


def _readonly(x: FloatArray) -> FloatArray:
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return x


@functools.cache
def _joint_limits() -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """POSITION_LOWER, POSITION_UPPER, VELOCITY_LIMITS, TORQUE_LIMITS, from the model."""
    model = load_pinocchio()[0]
    return (
        _readonly(model.lowerPositionLimit[7:]),
        _readonly(model.upperPositionLimit[7:]),
        _readonly(model.velocityLimit[6:]),
        _readonly(model.effortLimit[6:]),
    )


@functools.cache
def _foot_radius() -> float:
    geom = load_pinocchio()[1]
    return float(geom.geometryObjects[geom.getGeometryId(f"{FOOT_FRAMES[0]}_0")].geometry.radius)


def intrinsics(mount: CameraMount) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels of MuJoCo's rendering of `mount`.

    MuJoCo's fovy is vertical and its frustum symmetric, so fx = fy = (h/2)/tan(fovy/2)
    and the principal point is the image centre: with pixel centres at integer
    coordinates (OpenCV), cx = (w-1)/2, cy = (h-1)/2 (the test renders a point to check).
    """
    f = 0.5 * mount.height / math.tan(math.radians(mount.fovy_deg) / 2.0)
    return f, f, (mount.width - 1) / 2.0, (mount.height - 1) / 2.0


# --- postures -------------------------------------------------------------------------------
# Legs as in the SRDF's standing states (hip 0, thigh 0.8, calf -1.6); the arm per posture.
_LEGS_STAND = np.tile([0.0, 0.8, -1.6], len(LEG_NAMES))


def _posture(arm: tuple[float, ...], gripper: float) -> FloatArray:
    return _readonly(np.concatenate([_LEGS_STAND, arm, [gripper]]))


POSTURES: dict[str, FloatArray] = {
    # The SRDF's `standing_with_arm_home` (upper arm back along the trunk, forearm folded
    # forward over it) with the wrist lifted 4 cm, gripper level: at exactly 0, link06's
    # collision cylinder sinks 8 mm into link02's.
    "stand": _posture((0.0, 0.0, -0.2, 0.2, 0.0, 0.0), GRIPPER_CLOSED),
    # Carrying: folded as `stand`, jaw pivot vertical so a held bottle stays upright.
    "stow": _posture((0.0, 0.0, -0.2, 0.2, 0.0, math.pi / 2), GRIPPER_CLOSED),
    # Pre-grasp: gripper level and open at ~0.95 m, 0.55 m ahead, rolled for a side grasp.
    "ready": _posture((0.0, 0.46, -0.54, 0.08, 0.0, math.pi / 2), GRIPPER_OPEN),
    # Wrist camera 1.1 m up over the trunk front, pitched 14 deg down: sees a 0.75-1.1 m
    # high table top from 0.7 m to 1.3 m ahead (checked in the tests).
    "look": _posture((0.0, 0.64, -1.94, 1.28, 0.0, 0.0), GRIPPER_CLOSED),
    # Handover: the held object level, presented at 1.0 m height, 0.85 m ahead.
    "handover": _posture((0.0, 1.53, -0.96, -0.57, 0.0, math.pi / 2), GRIPPER_CLOSED),
}


def frame_in_base(q_joints: FloatArray, frame: str) -> pin.SE3:
    """`frame`'s pose in the base frame at the joint positions `q_joints` ((19,), the
    order of `RobotState.q`)."""
    import pinocchio as pin

    model = load_pinocchio()[0]
    q = pin.neutral(model)
    q[7:] = q_joints
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)]


@functools.cache
def _stand_base_height() -> float:
    """STAND_BASE_HEIGHT_M: the feet spheres rest on z = 0 in the `stand` legs."""
    return _foot_radius() - min(
        float(frame_in_base(POSTURES["stand"], f).translation[2]) for f in FOOT_FRAMES
    )


def quat_xyzw_of(R: FloatArray) -> FloatArray:
    """The unit quaternion (x, y, z, w) of a rotation matrix, through pinocchio at a few
    µs (scipy's `Rotation` takes 30-100 µs: too slow for the WBC's 500 Hz tick).
    `pin.Quaternion(R)` is not used: eigenpy's constructor from a matrix leaks 80 bytes a
    call, which at the odometry's one a tick grew the WBC by 2 MB a minute of a soak."""
    import pinocchio as pin

    quat = pin.SE3ToXYZQUAT(pin.SE3(np.asarray(R, dtype=float), np.zeros(3)))[3:]
    return np.asarray(quat / np.linalg.norm(quat), dtype=float)


def standing_q(
    posture: str = "stand", x: float = 0.0, y: float = 0.0, yaw: float = 0.0
) -> FloatArray:
    """Pinocchio q (26,) of the robot standing on z = 0 at (x, y, yaw) in `posture`."""
    if posture not in POSTURES:
        raise KeyError(f"unknown posture {posture!r}; postures are {sorted(POSTURES)}")
    quat = quat_xyzw_of(rot_z(yaw))
    return np.concatenate([[x, y, _stand_base_height()], quat, POSTURES[posture]])


# --- reach and standoff, from the arm's kinematics ------------------------------------------
GRASP_HEIGHTS_M = (0.75, 1.10)  # object centres on 0.7-1.0 m tables, held 5-10 cm up
GRASP_PITCH_RAD = (0.0, 0.5)  # side grasps from level to ~30 deg nose-down
COMFORT_MARGIN_RAD = 0.1  # a comfortable grasp stays this far inside every joint limit...
COMFORT_STRETCH = 0.9  # ...with the wrist at most 90 % of its farthest from the shoulder
APPROACH_MARGIN_M = 0.3  # navigation stops this far short of D_OPT; visual servoing closes it
#: A person's centre to the object held out to them, m: 0.15 m before their resting hand
#: (0.35 m: `services.sim.scene.HAND_IN_PERSON`), which takes what comes within 0.25 m.
#: It was 0.45 while perception put people 6 cm (to 13 cm) too near the camera, which
#: made it 0.51 (to 0.58); with that fixed, 0.45 presented the object 1-2 cm from the
#: hand's grip and the present posture's swing knocked it out (hall seed 3).
PERSON_REACH_M = 0.50
THETA_OPT_RAD = 0.0  # the object straight ahead: the arm works in the base's x-z plane


def _planar(theta: FloatArray, v: FloatArray) -> FloatArray:
    """Vectors v = (x, z) turned by angles theta about y: shape (len(theta), 2)."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    return np.hstack([v[0] * c + v[1] * s, -v[0] * s + v[1] * c])


@functools.cache
def arm_plane() -> dict[str, FloatArray]:
    """The arm at joint1 = joint5 = 0, joint6 = pi/2 (side grasp) in the base's x-z plane.

    joint2..joint4 turn about parallel y axes, so the TCP is shoulder + R(a2) upper +
    R(a2 + a3) fore + R(a2 + a3 + a4) tool, with these (x, z) vectors read from FK at zero.
    """
    import pinocchio as pin

    model = load_pinocchio()[0]
    ids = [model.getJointId(n) for n in ARM_JOINTS]
    if any(model.joints[ids[k]].shortname() != "JointModelRY" for k in (1, 2, 3)):
        raise ValueError("joint2..joint4 are no longer parallel y axes: arm_plane() is wrong")
    q = pin.neutral(model)
    q[7 + JOINT_NAMES.index("joint6")] = math.pi / 2
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    p = [data.oMi[i].translation[[0, 2]] for i in ids[1:4]]
    tcp = data.oMf[model.getFrameId(TCP_FRAME)].translation
    return {"shoulder": p[0], "upper": p[1] - p[0], "fore": p[2] - p[1], "tool": tcp[[0, 2]] - p[2]}


def _arm_grid(margin: float, n: int = 241) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(a2, a3, wrist position) over a grid of joint2, joint3 inside the limits - margin."""
    lo, hi, _, _ = _joint_limits()
    k2, k3 = JOINT_NAMES.index("joint2"), JOINT_NAMES.index("joint3")
    grid2, grid3 = np.meshgrid(
        np.linspace(lo[k2] + margin, hi[k2] - margin, n),
        np.linspace(lo[k3] + margin, hi[k3] - margin, n),
    )
    a2, a3 = grid2.ravel(), grid3.ravel()
    plane = arm_plane()
    wrist = plane["shoulder"] + _planar(a2, plane["upper"]) + _planar(a2 + a3, plane["fore"])
    return a2, a3, wrist


def _tcp_reachable(
    a2: FloatArray, a3: FloatArray, wrist: FloatArray, pitch: float, margin: float
) -> tuple[FloatArray, FloatArray]:
    """TCP (x, z) positions in the base frame with the tool at `pitch`, joint4 in limits."""
    lo, hi, _, _ = _joint_limits()
    k4 = JOINT_NAMES.index("joint4")
    a4 = pitch - a2 - a3
    ok = (a4 >= lo[k4] + margin) & (a4 <= hi[k4] - margin)
    return wrist + _planar(np.full_like(a2, pitch), arm_plane()["tool"]), ok


@functools.cache
def _limit_grid() -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """`_arm_grid` at the joint limits, and joint1's axis x in the base (at rest)."""
    import pinocchio as pin

    model = load_pinocchio()[0]
    q = pin.neutral(model)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    x1 = float(data.oMi[model.getJointId(ARM_JOINTS[0])].translation[0])
    return (*_arm_grid(0.0), x1)


def tcp_reach_gap(p_base: FloatArray, pitch_rad: float) -> float:
    """How far (m) a TCP at `p_base` (x, y, z in the base frame), nose-down `pitch_rad`
    in the arm's plane (joint1 turned toward it), lies outside what the arm reaches within
    its joint limits with the trunk at its standing pose; 0 inside (to the grid's ~1 cm).
    The whole-body controller moves the trunk too, so a few cm of gap may still be
    reached: the caller picks the slack.
    """
    a2, a3, wrist, x1 = _limit_grid()
    r = x1 + math.hypot(float(p_base[0]) - x1, float(p_base[1]))
    tcp, ok = _tcp_reachable(a2, a3, wrist, pitch_rad, 0.0)
    if not ok.any():
        return math.inf
    return float(np.min(np.hypot(tcp[ok, 0] - r, tcp[ok, 1] - float(p_base[2]))))


@functools.cache
def _reach_and_standoff() -> tuple[float, float]:
    """ARM_REACH_M: the farthest the TCP gets horizontally from the shoulder, any pitch.

    D_OPT_M: for every object height in GRASP_HEIGHTS_M, the comfortable grasps (see
    COMFORT_*) at a pitch in GRASP_PITCH_RAD put the TCP between x_min(h) and x_max(h)
    ahead of the base; D_OPT_M is the middle of what all heights share.
    """
    a2, a3, wrist = _arm_grid(0.0)
    reach = max(
        float(np.max(np.abs(tcp[ok, 0] - arm_plane()["shoulder"][0])))
        for tcp, ok in (_tcp_reachable(a2, a3, wrist, p, 0.0) for p in np.linspace(-1.5, 1.5, 61))
    )
    a2, a3, wrist = _arm_grid(COMFORT_MARGIN_RAD)
    stretch = np.linalg.norm(wrist - arm_plane()["shoulder"], axis=1)
    comfy = stretch <= COMFORT_STRETCH * stretch.max()
    lows, highs = [], []
    for h in np.linspace(*GRASP_HEIGHTS_M, 8):
        xs = []
        for pitch in np.linspace(*GRASP_PITCH_RAD, 11):
            tcp, ok = _tcp_reachable(a2, a3, wrist, pitch, COMFORT_MARGIN_RAD)
            hit = ok & comfy & (np.abs(tcp[:, 1] + _stand_base_height() - h) < 0.005)
            xs.extend(tcp[hit, 0])
        if not xs:
            raise ValueError(f"no comfortable side grasp reaches an object at {h:.2f} m")
        lows.append(min(xs))
        highs.append(max(xs))
    if max(lows) > min(highs):
        raise ValueError(f"no standoff suits every height: x_min {lows}, x_max {highs}")
    return reach, 0.5 * (max(lows) + min(highs))


@functools.cache
def _footprint(posture: str) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max) in `base_yaw` of every collision geometry, standing."""
    import pinocchio as pin

    model, geom = load_pinocchio()
    data, gdata = model.createData(), geom.createData()
    pin.updateGeometryPlacements(model, data, geom, gdata, standing_q(posture))
    corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1])).reshape(3, -1).T
    points = []
    for obj, placement in zip(geom.geometryObjects, gdata.oMg, strict=True):
        obj.geometry.computeLocalAABB()
        box = obj.geometry.aabb_local
        local = np.asarray(box.min_) + corners * (np.asarray(box.max_) - np.asarray(box.min_))
        points.append(local @ placement.rotation.T + placement.translation)
    lo, hi = np.vstack(points).min(axis=0), np.vstack(points).max(axis=0)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


@functools.cache
def posture_tcp(posture: str) -> tuple[float, float, float]:
    """The TCP (x, y, z, m) in the base frame with the robot standing in `posture`: where
    a carried object is (`stow`) and falls from."""
    import pinocchio as pin

    model = load_pinocchio()[0]
    data = model.createData()
    q = standing_q(posture)
    pin.framesForwardKinematics(model, data, q)
    T_world_tcp = data.oMf[model.getFrameId(TCP_FRAME)].homogeneous
    T_world_base = data.oMf[model.getFrameId(BASE_FRAME)].homogeneous
    x, y, z = (np.linalg.inv(T_world_base) @ T_world_tcp)[:3, 3]
    return float(x), float(y), float(z)


@functools.cache
def floor_view_m(posture: str = "look", height_m: float = 0.1, margin_deg: float = 5.0) -> float:
    """How far ahead of the base (m, standing, arm in `posture`) a point `height_m` above
    the floor first shows in the wrist camera, `margin_deg` inside its lower edge: where
    the robot stands to look at what fell at its feet (about 1.4 m in `look`)."""
    import pinocchio as pin

    model = load_pinocchio()[0]
    data = model.createData()
    pin.framesForwardKinematics(model, data, standing_q(posture))
    T = data.oMf[model.getFrameId("camera_wrist")].homogeneous
    T_base = data.oMf[model.getFrameId(BASE_FRAME)].homogeneous
    z_optical = T[:3, 2]  # the optical axis (OpenCV: z forward)
    down = math.atan2(-z_optical[2], math.hypot(z_optical[0], z_optical[1]))
    lowest = down + math.radians(CAMERA_MOUNTS["camera_wrist"].fovy_deg / 2 - margin_deg)
    ahead = float(T[0, 3] - T_base[0, 3])
    return ahead + float(T[2, 3] - height_m) / math.tan(lowest)


def posture_front_m(posture: str) -> float:
    """How far ahead of the base (m) the robot standing with its arm in `posture` reaches:
    its legs' front (0.435 m) or the arm's, whichever is farther."""
    return _footprint(posture)[1]


def _footprint_half_extents() -> tuple[float, float]:
    x_min, x_max, y_min, y_max = _footprint("stow")
    return max(-x_min, x_max), max(-y_min, y_max)


class Footprint(NamedTuple):
    """The robot's floor rectangle about the base origin, m: ahead, behind, to each side."""

    front: float
    back: float
    half_width: float

    @classmethod
    def stowed(cls) -> Footprint:
        """The rectangle of `FOOTPRINT_BOUNDS`: the robot with its arm stowed."""
        x_min, x_max, y_min, y_max = _footprint("stow")
        return cls(float(x_max), float(-x_min), float(max(-y_min, y_max)))

    @property
    def circumscribed(self) -> float:
        """The radius of the circle about the base origin that holds the rectangle, m."""
        return math.hypot(max(self.front, self.back), self.half_width)


# --- computed on first access ---------------------------------------------------------------
_LAZY: dict[str, Callable[[], object]] = {
    "POSITION_LOWER": lambda: _joint_limits()[0],
    "POSITION_UPPER": lambda: _joint_limits()[1],
    "VELOCITY_LIMITS": lambda: _joint_limits()[2],
    "TORQUE_LIMITS": lambda: _joint_limits()[3],
    "FOOT_RADIUS_M": _foot_radius,
    "STAND_BASE_HEIGHT_M": _stand_base_height,
    "ARM_REACH_M": lambda: _reach_and_standoff()[0],
    "D_OPT_M": lambda: _reach_and_standoff()[1],
    "STANDOFF_DISTANCE_M": lambda: _reach_and_standoff()[1] + APPROACH_MARGIN_M,
    "HANDOVER_DISTANCE_M": lambda: (
        float(frame_in_base(POSTURES["handover"], TCP_FRAME).translation[0]) + PERSON_REACH_M
    ),
    "FOOTPRINT_BOUNDS": lambda: _footprint("stow"),
    "FOOTPRINT": _footprint_half_extents,
}


def _lazy(name: str) -> object:
    """The value of the lazy module attribute `name`, computed now and kept as a global."""
    make = _LAZY.get(name)
    if make is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = make()
    globals()[name] = value  # later accesses are plain attribute lookups
    return value


if not TYPE_CHECKING:  # hidden from mypy, which types the lazy names from their declarations

    def __getattr__(name: str) -> object:  # PEP 562: called only for names not yet set
        return _lazy(name)


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
