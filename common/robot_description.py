"""The facts both robot models are built from: files, names, gripper and camera mounts.

Everything here is plain data, with no pinocchio or MuJoCo: `common.robot` builds the
pinocchio model and the simulator's `services.sim.mjcf` the MuJoCo one from the same URDF
text (`urdf_text()`), so the two cannot drift. That text is the example-robot-data URDF with
three edits: `package://` paths resolved, the base link's placeholder inertia (1e-6
everywhere, not positive definite) made diagonal, and the Z1 gripper's two collision
meshes removed — both models collide the gripper as the boxes in `GRIPPER_BOXES`, whose
sizes were read off the STL vertices (`read_stl`). Import `common.robot`, not this.
"""

from __future__ import annotations

import functools
import importlib.metadata
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.geometry import FloatArray, make_T, rot_y

# --- names (pinocchio's model order; `tests/unit/test_robot.py` checks it) ---------------

LEG_NAMES: tuple[str, ...] = ("FL", "FR", "RL", "RR")
LEG_JOINTS: tuple[str, ...] = tuple(
    f"{leg}_{part}_joint" for leg in LEG_NAMES for part in ("hip", "thigh", "calf")
)
ARM_JOINTS: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 7))
GRIPPER_JOINT = "jointGripper"
JOINT_NAMES: tuple[str, ...] = (*LEG_JOINTS, *ARM_JOINTS, GRIPPER_JOINT)
FOOT_FRAMES: tuple[str, ...] = tuple(f"{leg}_foot" for leg in LEG_NAMES)
BASE_FRAME = "base"
ROOT_JOINT = "root"  # MuJoCo's free joint (pinocchio's is `root_joint`)
STATOR_LINK = "gripperStator"
MOVER_LINK = "gripperMover"
TCP_FRAME = "gripper_tcp"

# --- gripper ---------------------------------------------------------------------------
# jointGripper turns the moving (upper, +z) jaw about the stator's y axis; 0 closes it onto
# the fixed (lower) jaw, negative angles swing it up, open. Pads meet at stator z = -9 mm.
GRIPPER_CLOSED = 0.0
GRIPPER_OPEN = -1.0
# Opened wider for a top grasp (joint limit -1.5707): open, a 6.3 cm box 3 cm into the jaws
# has 2.8 mm to the moving jaw's tip; at -1.3 rad, 24 mm.
GRIPPER_WIDE = -1.3
# gripper_tcp in the stator frame: x the approach direction (the stator's x), z from the
# fixed jaw towards the moving one, y along the jaw pivot: an upright bottle held in a side
# grasp lies along y (joint6 = +pi/2 turns y up). It sits mid-pad, 35 mm above the fixed
# pad, so a 60 mm bottle centred on it clears the fixed jaw by 5 mm before the jaw closes.
T_STATOR_TCP: FloatArray = make_T(p=(0.13, 0.0, 0.026))


@dataclass(frozen=True)
class CollisionBox:
    """A box collision primitive: centre and half sizes (m) in its link's frame."""

    name: str
    link: str
    center: tuple[float, float, float]
    half_size: tuple[float, float, float]
    is_jaw_pad: bool = False


# From the STL extents: stator body x in [-7, 75] mm, full height; fixed jaw x in [75, 149]
# mm under z = -9 mm; moving jaw (its frame at the pivot) x in [55, 100] mm above z = -9 mm.
GRIPPER_BOXES: tuple[CollisionBox, ...] = (
    CollisionBox("gripper_body", STATOR_LINK, (0.034, 0.0, 0.0), (0.041, 0.041, 0.0325)),
    CollisionBox(
        "gripper_jaw_fixed",
        STATOR_LINK,
        (0.112, 0.0, -0.0227),
        (0.037, 0.036, 0.0137),
        is_jaw_pad=True,
    ),
    CollisionBox("gripper_mover_body", MOVER_LINK, (0.017, 0.0, 0.010), (0.038, 0.041, 0.016)),
    CollisionBox(
        "gripper_jaw_moving",
        MOVER_LINK,
        (0.0775, 0.0, 0.0005),
        (0.0225, 0.034, 0.0095),
        is_jaw_pad=True,
    ),
)
JAW_GEOMS: tuple[str, ...] = tuple(b.name for b in GRIPPER_BOXES if b.is_jaw_pad)

# --- cameras ---------------------------------------------------------------------------
# OpenCV optical frame of a camera looking along its mount's +x, image up = mount's +z.
R_FORWARD_OPTICAL: FloatArray = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class CameraMount:
    """A camera: its OpenCV optical frame (z forward, x right, y down) on a parent frame.

    fovy_deg is the vertical field of view (MuJoCo's convention); pixels are square.
    """

    name: str
    parent_frame: str
    T_parent_camera: FloatArray = field(repr=False)
    fovy_deg: float
    width: int = 320
    height: int = 240
    rate_hz: float = 10.0


CAMERA_MOUNTS: dict[str, CameraMount] = {
    # On the trunk's front face under the arm base, pitched 20 deg down: the ground from
    # 0.5 m ahead to just above the horizon while walking, the arm base out of view.
    "camera_head": CameraMount(
        "camera_head",
        BASE_FRAME,
        make_T(rot_y(np.deg2rad(20.0)) @ R_FORWARD_OPTICAL, (0.34, 0.0, 0.05)),
        58.0,
    ),
    # Under the wrist on the fixed-jaw side, pitched 15 deg away from the jaws, so the
    # moving jaw never enters the image and the fixed one only grazes its top edge.
    "camera_wrist": CameraMount(
        "camera_wrist",
        STATOR_LINK,
        make_T(rot_y(np.deg2rad(15.0)) @ R_FORWARD_OPTICAL, (-0.03, 0.0, -0.06)),
        58.0,
    ),
}

# --- the other sensors ------------------------------------------------------------------
#: The IMU's frame: the URDF's `imu_link`, fixed on the trunk with the base's axes.
IMU_FRAME = "imu_link"


@dataclass(frozen=True)
class LidarMount:
    """A planar range scanner: its frame on a parent frame (x the scan's 0°, z up; beams
    sweep counter-clockwise about z)."""

    name: str
    parent_frame: str
    T_parent_lidar: FloatArray = field(repr=False)


#: On the trunk's front face, below the head camera and ahead of the front hips (their
#: rotors reach x = 0.44 m): the plane at about 0.5 m above the floor while standing,
#: above the pallets' tops and below the tables', through walls, shelves' uprights and
#: people's legs. Beams behind about ±100° meet the robot's own legs and are masked.
LIDAR_MOUNT = LidarMount(
    "lidar",
    BASE_FRAME,
    make_T(np.eye(3), (0.46, 0.0, -0.03)),
)
#: Its twin on the trunk's back face, facing back (behind the rear hips' rotors, which
#: reach x = −0.44 m): between them the two 270° fields cover all round, as an industrial
#: platform's two scanners do. The front one's ±100° left a person walking up from behind
#: unseen (hall seed 0's shift, 132° off the heading).
LIDAR_REAR_MOUNT = LidarMount(
    "lidar_rear",
    BASE_FRAME,
    make_T(np.diag([-1.0, -1.0, 1.0]), (-0.46, 0.0, -0.03)),
)

# --- joint dynamics: dume's choices where the URDF has none -----------------------------
# Reflected rotor inertia (kg m^2): B1 legs have geared rotors (the knee the most), which
# also keeps light links stable at 1 kHz; the Z1 and its jaw get a small one.
_LEG_ARMATURE = {"hip": 0.05, "thigh": 0.05, "calf": 0.1}
ARM_ARMATURE = 0.01
GRIPPER_ARMATURE = 0.005
LEG_DAMPING = 0.5  # N m s/rad; the URDF's legs have none, the arm keeps the URDF's values


# --- files -------------------------------------------------------------------------------


def robots_dir() -> Path:
    """example-robot-data's `robots/` folder in the installed package."""
    dist = importlib.metadata.distribution("example-robot-data")
    path = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    if not path.is_dir():
        raise FileNotFoundError(f"example-robot-data {dist.version}: no robots folder at {path}")
    return path


def urdf_path() -> Path:
    return robots_dir() / "b1_description" / "urdf" / "b1-z1.urdf"


def srdf_path() -> Path:
    return robots_dir() / "b1_description" / "srdf" / "b1-z1.srdf"


def gripper_stl_path(link: str) -> Path:
    """The Z1 collision STL of `gripperStator` or `gripperMover`."""
    stem = {STATOR_LINK: "z1_GripperStator", MOVER_LINK: "z1_GripperMover"}[link]
    return robots_dir() / "z1_description" / "meshes" / "collision" / f"{stem}.STL"


_BASE_INERTIA = '<inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"/>'
_BASE_INERTIA_DIAGONAL = '<inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/>'
_GRIPPER_MESH_COLLISION = re.compile(
    r"<collision>\s*<geometry>\s*<mesh [^>]*z1_Gripper(?:Stator|Mover)\.STL[^>]*/>\s*"
    r"</geometry>\s*</collision>"
)


@functools.cache
def urdf_text() -> str:
    """The URDF both models load (see the module docstring for the three edits)."""
    text = urdf_path().read_text()
    text = text.replace("package://example-robot-data/", robots_dir().parent.as_posix() + "/")
    if _BASE_INERTIA not in text:
        raise ValueError(f"{urdf_path()}: the base link's placeholder inertia has changed")
    text = text.replace(_BASE_INERTIA, _BASE_INERTIA_DIAGONAL)
    text, n = _GRIPPER_MESH_COLLISION.subn("", text)
    if n != 2:
        raise ValueError(f"{urdf_path()}: expected 2 gripper collision meshes, found {n}")
    return text


@dataclass(frozen=True)
class UrdfJoint:
    """What the URDF declares for a revolute joint: damping (N m s/rad), friction and
    effort limit (N m)."""

    damping: float
    friction: float
    effort: float


@functools.cache
def urdf_joints() -> dict[str, UrdfJoint]:
    """The URDF's revolute joints by name."""
    out = {}
    for joint in ET.fromstring(urdf_text()).iter("joint"):
        if joint.get("type") != "revolute":
            continue
        dyn = joint.find("dynamics")
        limit = joint.find("limit")
        out[joint.get("name", "")] = UrdfJoint(
            damping=float(dyn.get("damping", 0.0)) if dyn is not None else 0.0,
            friction=float(dyn.get("friction", 0.0)) if dyn is not None else 0.0,
            effort=float(limit.get("effort", 0.0)) if limit is not None else 0.0,
        )
    return out


@functools.cache
def srdf_disabled_pairs() -> tuple[tuple[str, str], ...]:
    """The SRDF's `disable_collisions` link pairs."""
    root = ET.parse(srdf_path()).getroot()
    return tuple((e.get("link1", ""), e.get("link2", "")) for e in root.iter("disable_collisions"))


def read_stl(path: Path) -> FloatArray:
    """Vertices (3 per triangle, (n, 3), m) of a binary STL file."""
    raw = path.read_bytes()
    count = int(np.frombuffer(raw, dtype="<u4", count=1, offset=80)[0])
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
    if len(raw) != 84 + count * record.itemsize:
        raise ValueError(f"{path}: not a binary STL ({len(raw)} bytes for {count} triangles)")
    triangles = np.frombuffer(raw, dtype=record, count=count, offset=84)
    return triangles["vertices"].reshape(-1, 3).astype(np.float64)


def joint_armature() -> FloatArray:
    """Armature (kg m^2) per joint in `JOINT_NAMES` order."""
    out = [ARM_ARMATURE] * len(JOINT_NAMES)
    for i, name in enumerate(JOINT_NAMES):
        if name in LEG_JOINTS:
            out[i] = _LEG_ARMATURE[name.split("_")[1]]
        elif name == GRIPPER_JOINT:
            out[i] = GRIPPER_ARMATURE
    return np.array(out)


def joint_damping() -> FloatArray:
    """Viscous damping (N m s/rad) per joint: the URDF's, or `LEG_DAMPING` on the legs."""
    urdf = urdf_joints()
    return np.array([LEG_DAMPING if n in LEG_JOINTS else urdf[n].damping for n in JOINT_NAMES])


def joint_frictionloss() -> FloatArray:
    """Dry friction (N m) per joint, as the URDF declares it (the arm and jaw only)."""
    return np.array([urdf_joints()[n].friction for n in JOINT_NAMES])
