"""What the simulator publishes and what it takes: clock, state, command, cameras, events.

Joint vectors are `Array`s of float64 in `common.robot.JOINT_NAMES` order (pinocchio's
order: FL, FR, RL, RR legs hip/thigh/calf; arm joint1–6; the gripper jaw), 19 entries.
The base is reported separately: position in world, orientation x y z w, linear
velocity in world and angular velocity in the base frame.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from common.messages.arrays import Array
from common.messages.base import (
    EntityId,
    Finite,
    Mat4,
    Message,
    NonNegative,
    QuatXYZW,
    StampNs,
    Vec3,
    check_unit_quaternion,
)

TimeMode = Literal["lockstep", "realtime"]
Locomotion = Literal["dynamic", "kinematic"]


class Clock(Message, frozen=True):
    """`dume/world/clock`: sim time, published every tick.

    stamp_ns: sim time of the tick, ns. tick: tick count since start (1 kHz).
    mode: lockstep or realtime. rtf: real-time factor over the last second of wall time.
    """

    stamp_ns: StampNs
    tick: int
    mode: TimeMode
    rtf: NonNegative = 0.0

    WALL_CLOCK = ("rtf",)


class SimStats(Message, frozen=True):
    """`dume/<r>/sim/stats`, every sim second: where the sim's wall time went, cumulative
    from its first tick (for `dume bench stack`; nothing in the robot's loop reads it).

    ticks: physics steps taken. wall_s: the loop's wall seconds. step_s: in the physics
    step (contacts, people and handover included). render_s, captures: per camera, the
    wall seconds rendering and how many captures. publish_s: putting out everything else
    stamped (state, odom, frames' encoding and sending, clock, recording). waited_s: per
    lockstep participant, the wall seconds the sim waited for it (a wait is booked to the
    participant that answered last, the one the sim was blocked on). stalls: lockstep
    waits that ran out (`time.stall_timeout_s`: the sim stepped on without a participant,
    each logged), 0 in a run that kept lockstep.
    """

    stamp_ns: StampNs
    ticks: int
    wall_s: NonNegative
    step_s: NonNegative
    render_s: dict[str, NonNegative]
    captures: dict[str, int]
    publish_s: NonNegative
    waited_s: dict[str, NonNegative]
    stalls: int = 0

    WALL_CLOCK = ("wall_s", "step_s", "render_s", "publish_s", "waited_s")


class RobotState(Message, frozen=True):
    """`dume/<r>/state`, 1 kHz: everything the whole-body controller needs.

    q, v, tau: (19,) float64 joint positions (rad), velocities (rad/s) and the torques
        applied during the last step (N·m, after clipping to the URDF limits).
    foot_contacts: FL, FR, RL, RR touching the ground. foot_forces: (4,) normal force, N.
    imu_angular_velocity: (3,) rad/s and imu_specific_force: (3,) m/s², the trunk IMU's
        sample in its frame (`common.robot.IMU_FRAME`, the base's axes): the specific
        force is acceleration minus gravity (about +9.81 up when at rest).
    q, v, the feet and the IMU are measured (`services.sim.sensors`: quantised, noisy,
    biased), as a robot's low-level state (Unitree's `LowState`) reports them. The base's
    pose and twist are not here: a robot works them out (the WBC's odometry); the sim's
    are on `state_truth`.
    gripper_angle: jaw angle, rad (0 closed, negative open). gripper_effort: jaw torque, N·m.
    watchdog: the sim's hold is engaged (no command for 20 ms); watchdog_reason says why.
    locomotion: dynamic (torques move the legs) or kinematic (the base follows cmd_vel).
    """

    stamp_ns: StampNs
    tick: int
    q: Array
    v: Array
    tau: Array
    foot_contacts: tuple[bool, bool, bool, bool]
    foot_forces: tuple[Finite, Finite, Finite, Finite]
    imu_angular_velocity: Vec3
    imu_specific_force: Vec3
    gripper_angle: Finite
    gripper_effort: Finite
    watchdog: bool = False
    watchdog_reason: str = ""
    locomotion: Locomotion = "dynamic"


class Odom(Message, frozen=True):
    """`dume/<r>/odom`, 50 Hz: the base and gripper for the slower services: the WBC's
    estimate (`wbc.base_state = "estimate"`), or the sim's free joint (the truth ablation,
    kinematic locomotion).

    base_position_in_world m, base_orientation_xyzw, base_linear_velocity_in_world m/s,
    base_angular_velocity_in_base rad/s; the gripper and the sim's flags as in
    `RobotState`.
    """

    stamp_ns: StampNs
    base_position_in_world: Vec3
    base_orientation_xyzw: QuatXYZW
    base_linear_velocity_in_world: Vec3
    base_angular_velocity_in_base: Vec3
    gripper_angle: Finite
    gripper_effort: Finite
    watchdog: bool = False
    locomotion: Locomotion = "dynamic"

    def __post_init__(self) -> None:
        check_unit_quaternion(self.base_orientation_xyzw, "base_orientation_xyzw")


class StateTruth(Message, frozen=True):
    """`dume/<r>/state_truth`: the base as the simulator knows it (MuJoCo's free joint), at
    `sim.odom_hz`, or every tick for the WBC's truth ablation (`wbc.base_state =
    "truth"`). Truth: read by evaluation, tests, trials and that ablation only.

    Fields as in `Odom`: position m, orientation xyzw, linear velocity m/s in world,
    angular velocity rad/s in base.
    """

    stamp_ns: StampNs
    base_position_in_world: Vec3
    base_orientation_xyzw: QuatXYZW
    base_linear_velocity_in_world: Vec3
    base_angular_velocity_in_base: Vec3

    def __post_init__(self) -> None:
        check_unit_quaternion(self.base_orientation_xyzw, "base_orientation_xyzw")


class LaserScan(Message, frozen=True):
    """`dume/<r>/scan`, 10 Hz: one sweep of the trunk's planar lidar.

    ranges: (n,) float32 m, 0 = no return; beam k at angle_min + k angle_increment (rad,
    counter-clockwise about the lidar's z from its x). range_min, range_max: m.
    T_base_lidar: the lidar's frame in the base (row-major 4×4). The sweep is taken at
    stamp_ns as a whole (the sim casts every beam at once).
    """

    stamp_ns: StampNs
    angle_min: Finite
    angle_increment: Finite
    range_min: Finite
    range_max: Finite
    ranges: Array
    T_base_lidar: Mat4


class JointCommand(Message, frozen=True):
    """`dume/<r>/command`, per tick: τ = τ_ff + kp (q_des − q) + kd (v_des − v), clipped.

    stamp_ns: the stamp of the `RobotState` this command answers (lockstep waits for it).
    tau_ff: (19,) N·m. q_des: (19,) rad. v_des: (19,) rad/s.
    kp: (19,) N·m/rad, ≥ 0. kd: (19,) N·m·s/rad, ≥ 0.
    source: who sent it (`wbc`, a test controller, …).
    """

    stamp_ns: StampNs
    tau_ff: Array
    q_des: Array
    v_des: Array
    kp: Array
    kd: Array
    source: str = "wbc"


class CameraFrame(Message, frozen=True):
    """`dume/<r>/camera/<cam>/rgbd`, 10 Hz: one RGB-D capture.

    rgb: (H, W, 3) uint8. depth: (H, W) float32, metres along the optical axis, 0 = no return.
    fx, fy, cx, cy: pinhole intrinsics in pixels (pixel centres at integer coordinates).
    T_base_camera: camera optical frame (OpenCV: z forward, x right, y down) in the base
        frame at capture (the robot's kinematics: a real one computes it from its joint
        encoders). Where the base was at capture is not here: that is the robot's own
        estimate, `odom` at the frame's stamp.
    """

    stamp_ns: StampNs
    camera: str
    width: int
    height: int
    fx: Finite
    fy: Finite
    cx: Finite
    cy: Finite
    rgb: Array
    depth: Array
    T_base_camera: Mat4


class SegmentationTruth(Message, frozen=True):
    """`dume/<r>/camera/<cam>/segmentation_truth`: the renderer's instance ids (sim truth).

    labels: (H, W) int32 instance label per pixel, 0 for the background.
    instances: label → truth instance id (`bottle_1`, `person_2`, …).
    """

    stamp_ns: StampNs
    camera: str
    labels: Array
    instances: dict[int, str]


class HandoverTaken(Message, frozen=True, tag="handover_taken"):
    """A person gripped the object the robot presented (truth, for evaluation)."""

    stamp_ns: StampNs
    person_id: EntityId
    object_id: EntityId


class ObjectDropped(Message, frozen=True, tag="object_dropped"):
    """An artifact fell: its height dropped by more than 10 cm while nobody held it."""

    stamp_ns: StampNs
    object_id: EntityId
    position_in_world: Vec3


class RobotContact(Message, frozen=True, tag="robot_contact"):
    """A robot body other than a foot touched something in the world (begins).

    body: the robot body. other: the world object (obstacle id, artifact id, `floor`).
    """

    stamp_ns: StampNs
    body: str
    other: str
    position_in_world: Vec3
    force: NonNegative


class ArtifactPose(Message, frozen=True):
    """An artifact as the simulator has it: its body's origin in the world (m) and how
    upright it stands (the cosine of its tilt: 1 upright, 0 lying)."""

    id: EntityId
    position_in_world: Vec3
    upright: Annotated[float, msgspec.Meta(ge=-1.0, le=1.0)]


class ArtifactsTruth(Message, frozen=True):
    """The answer of `dume/world/artifacts` (truth: tests and evaluation only): every
    artifact of the world where it is at `stamp_ns` (the sim's snapshot, every 0.1 s of
    sim time)."""

    stamp_ns: StampNs
    artifacts: list[ArtifactPose]


class ArtifactMoved(Message, frozen=True, tag="artifact_moved"):
    """Somebody moved an artifact (the changing hall's hook, `ArtifactCommand`): where its
    base now is (truth, for evaluation); `away`: out of the hall."""

    stamp_ns: StampNs
    object_id: EntityId
    position_in_world: Vec3
    away: bool = False


class MovableMoved(Message, frozen=True, tag="movable_moved"):
    """Somebody left a movable (a trolley) somewhere (the changing hall's hook,
    `MovableCommand`): where its centre now stands and its heading (truth, for
    evaluation); `away`: parked beyond the hall's walls again."""

    stamp_ns: StampNs
    movable_id: EntityId
    position_in_world: tuple[Finite, Finite]
    yaw: Finite = 0.0
    away: bool = False


WorldEvent = HandoverTaken | ObjectDropped | RobotContact | ArtifactMoved | MovableMoved


class PersonTruth(Message, frozen=True):
    """One person as the sim moves them: floor point (m), heading (rad), velocity (m/s)."""

    id: EntityId
    position: tuple[Finite, Finite]
    yaw: Finite
    velocity: tuple[Finite, Finite]


class PeopleTruth(Message, frozen=True):
    """`dume/world/people`: where every person is, at the lidar's rate, for whoever
    listens (truth: evaluation and tests only, the separation from people judged)."""

    stamp_ns: StampNs
    people: list[PersonTruth]


class WorldEvents(Message, frozen=True):
    """`dume/world/events`: events of one tick (truth: evaluation and tests only)."""

    stamp_ns: StampNs
    events: list[WorldEvent]


class Push(Message, frozen=True):
    """`dume/world/push` (tests and evaluation only; the sim alone reads it): an external
    force on the robot's base, a disturbance for the controller to survive.

    stamp_ns: sim time the push starts; the sim applies it from its step at that time
        (lockstep-deterministic when it arrives before: publish it a participant period
        or more ahead; a late one is applied at once and logged).
    force_in_world: (3,) N on the base body's centre of mass, world axes.
    duration_s: how long, s, in (0, 10]; the impulse is force × duration
        (200 N for 0.1 s = 20 N·s).
    target: `base`, or an artifact's id: a knock on what the robot carries (a slip).
    """

    stamp_ns: StampNs
    force_in_world: Vec3
    duration_s: Annotated[float, msgspec.Meta(gt=0.0, le=10.0)]
    target: Annotated[
        str, msgspec.Meta(pattern=r"^(base|[a-z][a-z0-9]*_[1-9][0-9]*)$", max_length=64)
    ] = "base"


class ArtifactCommand(Message, frozen=True):
    """`dume/world/artifact_command` (tests and evaluation only; the sim alone reads it):
    somebody moves an artifact, the changing hall's parts moved from bench to bench.

    stamp_ns: sim time it takes effect, at the sim's step then (publish it ahead).
    artifact_id: the world's artifact (`bottle_1`).
    position: (3,) m, world: the point its base then rests on (a support's top under it),
        at rest, upright; None with `away`.
    yaw: rad, its heading there.
    away: taken out of the hall (parked beyond its walls, out of every camera's sight).
    """

    stamp_ns: StampNs
    artifact_id: EntityId
    position: Vec3 | None = None
    yaw: Finite = 0.0
    away: bool = False


class MovableCommand(Message, frozen=True):
    """`dume/world/movable_command` (tests and evaluation only; the sim alone reads it):
    somebody leaves a movable (`WorldDescription.movables`: a trolley) in the hall, or
    takes it away again.

    stamp_ns: sim time it takes effect, at the sim's step then (publish it ahead).
    movable_id: the world's movable (`trolley_1`).
    position: (2,) m, world: where its centre then stands, on the hall's floor (the
        caller chooses free floor: `services.sim.world.aisle_spot`); None with `away`.
    yaw: rad, its heading there.
    away: parked beyond the hall's walls again.
    """

    stamp_ns: StampNs
    movable_id: EntityId
    position: tuple[Finite, Finite] | None = None
    yaw: Finite = 0.0
    away: bool = False


class PersonCommand(Message, frozen=True):
    """`dume/world/people_command` (tests and evaluation only; the sim alone reads it): move
    one person of the world, e.g. to step into the robot's path.

    stamp_ns: sim time it takes effect; applied at the sim's step at that time (publish it
        a participant period or more ahead for a lockstep-deterministic run; a late one is
        applied at once and logged).
    person_id: the world's person (`person_1`).
    position: (2,) m, world: teleport the person there first (None: where they are).
    yaw: rad, the direction they face after a teleport (None: unchanged).
    walk_to: (k, 2) m, world: floor points walked in order at `speed`, then the person
        stands at the last one; empty: they stand where they are (their own route is
        dropped either way).
    speed: m/s along `walk_to`, (0, 1.2].
    ignore_robot: the person no longer stops and turns to face the robot when it comes
        within 3 m (`services.sim.people.FACE_RADIUS_M`): they walk through their route.
    """

    stamp_ns: StampNs
    person_id: EntityId
    position: tuple[Finite, Finite] | None = None
    yaw: Finite | None = None
    walk_to: tuple[tuple[Finite, Finite], ...] = ()
    speed: Annotated[float, msgspec.Meta(gt=0.0, le=1.2)] = 1.0
    ignore_robot: bool = True


class CameraInfo(Message, frozen=True):
    """A camera mount: parent frame, `T_parent_camera` (optical), intrinsics and rate."""

    name: str
    parent_frame: str
    T_parent_camera: Mat4
    width: int
    height: int
    fx: Finite
    fy: Finite
    cx: Finite
    cy: Finite
    rate_hz: Finite


class RobotDescription(Message, frozen=True):
    """`dume/<r>/description` (queryable): the robot as the sim runs it.

    joint_names: the 19 joints in order. lower, upper: rad. velocity: rad/s. effort: N·m.
    frames: named frames (feet, gripper_tcp, cameras). tick_hz: physics and state rate.
    """

    robot: str
    joint_names: tuple[str, ...]
    lower: tuple[Finite, ...]
    upper: tuple[Finite, ...]
    velocity: tuple[Finite, ...]
    effort: tuple[Finite, ...]
    frames: tuple[str, ...]
    cameras: tuple[CameraInfo, ...]
    tick_hz: Finite
    locomotion: Locomotion
    mode: TimeMode


class Ack(Message, frozen=True):
    """`dume/<r>/ack/<service>`: `service` has fully processed the tick at `stamp_ns`."""

    service: str
    stamp_ns: StampNs
