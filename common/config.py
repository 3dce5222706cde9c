"""Settings: the Structs below, then `deploy/config.toml`, then `DUME_*` variables, then flags.

The schema is a tree of msgspec Structs that forbid unknown fields, so a misspelt key in
the file, the environment or a flag fails at start-up with the key's path. The Structs
are the one source of every setting's default, unit and range (`Annotated` with
`msgspec.Meta`: checked as the settings load); `deploy/config.toml` holds only what a
deployment decides (the robot, the router's address, the lockstep participants). Overrides:

- environment: `DUME_<SECTION>_<KEY>=value`, e.g. `DUME_ZENOH_PORT=7450`,
  `DUME_SIM_WORLD_SEED=3`, `DUME_TIME_MODE=realtime`, and for a key of a nested section
  `DUME_<SECTION>_<SUB>_<KEY>`, e.g. `DUME_NAVIGATION_CONTROLLER_V_MAX="[0.4, 0.3, 0.8]"`;
  `DUME_CONFIG` names another file.
- `DUME_SETTINGS`: a JSON file of overrides as data, `{"section.key": value}` with keys of
  any depth (what a stack launcher writes once per run for every process), applied after
  the variables above.
- overrides given to `load_config`: data (`{"sim.world": "small"}`, the launchers' and
  tests' way), or flags, `--set section.key=value` strings of any depth (e.g.
  `time.participants.wbc.period_s=0.002`), parsed once by `parse_overrides`.

A flag's value is parsed as a TOML literal (`3`, `0.5`, `true`, `"text"`, `[1, 2]`);
anything that is not a literal is taken as a string.
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec

from common.messages.base import NS_PER_S

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_CONFIG = REPO_ROOT / "deploy" / "config.toml"
ENV_PREFIX = "DUME_"
#: Environment variables that are not settings.
ENV_NOT_SETTINGS = frozenset(
    {"DUME_CONFIG", "DUME_SETTINGS", "DUME_PYTHON", "DUME_RUN_DIR", "DUME_USER",
     "DUME_CTL_PASSWORD"}
)  # fmt: skip
#: Environment variables under this prefix are not settings either: `DUME_START_<SERVICE>`
#: tells supervisord which services a host runs (`deploy.stack.stack_env`).
ENV_START = "DUME_START_"
#: Overrides as data: a dotted key path (`"time.participants.wbc.period_s"`) → its value.
Overrides = Mapping[str, Any]


#: Ranges a setting's type carries (msgspec checks them as the settings load).
Port = Annotated[int, msgspec.Meta(ge=1, le=65535, description="a TCP port")]
Positive = Annotated[float, msgspec.Meta(gt=0)]
NonNegative = Annotated[float, msgspec.Meta(ge=0)]
#: A coordinate or any other real number: finite (no NaN, no infinity).
FiniteFloat = Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]
#: A score or share, [0, 1].
Fraction = Annotated[float, msgspec.Meta(ge=0, le=1)]
PositiveInt = Annotated[int, msgspec.Meta(ge=1)]
NonNegativeInt = Annotated[int, msgspec.Meta(ge=0)]
Unit = Annotated[float, msgspec.Meta(ge=0, le=1)]
#: (vx m/s, vy m/s, wz rad/s) limits, or their rates of change per s.
Limits3 = Annotated[list[Positive], msgspec.Meta(min_length=3, max_length=3)]


class ConfigError(ValueError):
    """Configuration that cannot be used: which key, what was given, what is valid."""


class _Section(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    pass


class ZenohSettings(_Section):
    """The router's address. Services are clients of one router per stack.

    access_control: every session logs in (user and password from `credentials`, made
    at first use) and the router allows each identity only its keys (`common.access`).
    Off only for a session with a tool that cannot log in, on a host nobody else uses.

    side: the stack on one host (`all`), or one of two hosts linked router to router
    (`dume up --host robot|station`): the robot runs every service but the map
    (`common.access.SIDES`), and its router listens for the station's on
    `link_host:link_port` (TLS, both certificates checked); the station runs the
    semantic map, and its router connects there. `certs`: the folder of the link's
    certificates and secret (`dume certs`, `common.certs`).

    robots: the robots besides the stack's own (`robot`) whose services may log in to
    this router, each under identities of its own (`b2.mission`) that reach only its
    keys (`common.access`).
    """

    host: str = "127.0.0.1"
    port: Port = 7447
    router_config: str = "deploy/zenoh/router.json5"
    client_config: str = "deploy/zenoh/client.json5"
    access_control: bool = True
    credentials: str = "var/secrets/zenoh-users"
    side: Literal["all", "robot", "station"] = "all"
    link_host: str = "127.0.0.1"
    link_port: Port = 7448
    certs: str = "var/secrets/certs"
    robots: list[str] = msgspec.field(default_factory=list)

    def __post_init__(self) -> None:
        if self.side != "all" and not self.access_control:
            raise ValueError(
                f"zenoh.side {self.side!r} needs zenoh.access_control: the link between "
                "hosts is only ever opened to the other host's router, logged in"
            )
        if self.side != "all" and self.link_port == self.port:
            raise ValueError(f"zenoh.link_port {self.link_port} is the router's own port")


class Participant(_Section):
    """A lockstep participant.

    role: `command` (answers every state it gets with a command; the sim waits for it
    before stepping), `periodic` (ticks on sim time every `period_s`; its outputs take
    effect `latency_s` after their input, and the sim never steps past that before the
    participant's ack for the input has arrived) or `start` (a client the sim waits for
    at t = 0 and never again: the demo and the eval hand their request to the mission
    before they come alive, so it starts at the mission's first tick in every run;
    `period_s` and `latency_s` unused).
    """

    role: Literal["command", "periodic", "start"] = "periodic"
    period_s: Positive = 0.1
    latency_s: NonNegative = 0.05


class TimeSettings(_Section):
    #: `lockstep` (the sim steps when every participant has caught up: deterministic) or
    #: `realtime` (paced to the wall clock, nobody waited for).
    mode: Literal["lockstep", "realtime"] = "lockstep"
    tick_hz: Positive = 1000.0
    participants: dict[str, Participant] = msgspec.field(default_factory=dict)
    #: Wall seconds the sim waits at t = 0 for every participant to be alive.
    start_timeout_s: Positive = 120.0
    #: Wall seconds a live participant may take on one tick before the sim logs it as
    #: stalled and steps without it (the robot's watchdog then acts, as on hardware). A
    #: dead one is not waited for at all (its liveliness goes), so this only catches a
    #: hung process; long enough that a slow tick on a loaded machine (a first plan,
    #: two stacks on two cores) never breaks the run's determinism.
    stall_timeout_s: Positive = 10.0

    def period_of(self, name: str, default_s: float) -> float:
        """`name`'s lockstep period, s; `default_s` when it is not a participant."""
        p = self.participants.get(name)
        return p.period_s if p is not None else default_s

    def period_ns_of(self, name: str, default_s: float) -> int:
        return round(self.period_of(name, default_s) * NS_PER_S)

    def latency_ns_of(self, name: str, default_s: float) -> int:
        """`name`'s lockstep latency, ns; `default_s` when it is not a participant."""
        p = self.participants.get(name)
        return round((p.latency_s if p is not None else default_s) * NS_PER_S)

    def latencies_ns(self) -> dict[str, int]:
        """Every participant's latency, ns: what a consumer adds to a producer's stamp."""
        return {n: round(p.latency_s * NS_PER_S) for n, p in self.participants.items()}


class ImuSettings(_Section):
    """The trunk's MEMS IMU, read every physics step (1 kHz), white noise plus a bias that
    starts somewhere and wanders. Densities from the Bosch BMI088 datasheet (gyroscope
    0.014 °/s/√Hz, accelerometer 175 µg/√Hz); the bias random walks are those a Kalibr
    calibration of it typically gives; the turn-on biases are left after the factory's
    calibration (well inside the datasheet's ±1 °/s and ±20 mg offsets)."""

    gyro_noise_density: NonNegative = 2.4e-4  # rad/s/√Hz
    gyro_bias_walk: NonNegative = 2.0e-5  # rad/s²/√Hz
    gyro_bias_initial: NonNegative = 1.7e-3  # rad/s, σ per axis (0.1 °/s)
    accel_noise_density: NonNegative = 1.7e-3  # m/s²/√Hz
    accel_bias_walk: NonNegative = 4.0e-4  # m/s³/√Hz
    accel_bias_initial: NonNegative = 0.05  # m/s², σ per axis


class JointSensorSettings(_Section):
    """Joint encoders (absolute, at the joint) and the feet's force sensors."""

    #: Counts per joint turn: positions are quantised to 2π / counts (16 bits: 96 µrad).
    encoder_counts: Annotated[int, msgspec.Meta(ge=0)] = 65536
    #: σ of the white noise on the drives' velocity estimates, rad/s.
    velocity_noise: NonNegative = 0.02
    #: σ of the feet's force readings, N; a foot is in contact above `contact_force_n`.
    foot_force_noise: NonNegative = 5.0
    contact_force_n: NonNegative = 20.0


class LidarSettings(_Section):
    """The trunk's planar laser scanner (`common.robot.LIDAR_MOUNT`), cast with MuJoCo's
    rays against everything but the robot. As a Hokuyo UST-10LX (270°, 10 m, ±40 mm):
    0.5° beams at 10 Hz, Gaussian range noise, beams lost at random; a beam that meets the
    robot's own body is masked (no return), as the driver's angular mask would."""

    rate_hz: Positive = 10.0
    fov_deg: Annotated[float, msgspec.Meta(gt=0.0, le=360.0)] = 270.0
    beams: Annotated[int, msgspec.Meta(ge=2)] = 541
    range_min_m: NonNegative = 0.1
    range_max_m: Positive = 10.0
    range_noise_m: NonNegative = 0.015
    dropout: Unit = 0.01
    #: Its twin on the trunk's back (`common.robot.LIDAR_REAR_MOUNT`, on `scan_rear`):
    #: the two fields cover all round (navigation's protective field).
    rear: bool = True


class DepthNoiseSettings(_Section):
    """The RGB-D cameras' depth errors, as a stereo sensor's (Intel RealSense D435's
    model: σ grows with the square of the range): σ(z) = `sigma_per_m2` z², no return on
    the farther side of a jump of more than `edge_jump_m` between neighbours (stereo's
    occlusion band beside a nearer edge), and pixels lost at random."""

    enabled: bool = True
    sigma_per_m2: NonNegative = 0.0025
    edge_jump_m: Positive = 0.1
    dropout: Unit = 0.005


class SensorSettings(_Section):
    """What the robot measures, with its errors (`services.sim.sensors`), seeded by
    `sim.world_seed`: the same seed, the same noise."""

    imu: ImuSettings = msgspec.field(default_factory=ImuSettings)
    joints: JointSensorSettings = msgspec.field(default_factory=JointSensorSettings)
    lidar: LidarSettings = msgspec.field(default_factory=LidarSettings)
    depth: DepthNoiseSettings = msgspec.field(default_factory=DepthNoiseSettings)


class SimSettings(_Section):
    world: Literal["hall", "small"] = "hall"
    world_seed: NonNegativeInt = 0
    walking_people: bool = False
    #: With `walking_people`: people keep to their routes past the robot and across its
    #: path, stop only for a robot that comes to them carrying something, and pause rather
    #: than walk into it (`services/sim/people.py`).
    bystanders: bool = False
    locomotion: Literal["dynamic", "kinematic"] = "dynamic"
    #: Stop after this much sim time (0: run until stopped).
    duration_s: NonNegative = 0.0
    watchdog_ms: Positive = 20.0
    odom_hz: Positive = 50.0
    camera_hz: Positive = 10.0
    camera_width: PositiveInt = 320
    camera_height: PositiveInt = 240
    cameras: list[str] = msgspec.field(default_factory=lambda: ["camera_head", "camera_wrist"])
    segmentation_truth: bool = True
    sensors: SensorSettings = msgspec.field(default_factory=SensorSettings)


class GaitSettings(_Section):
    """The trot's command shaping (`services/wbc/gait.py`): every cmd_vel obeyed is clamped
    to `v_max` and moved towards at most `a_max` per s (`d_max` while |v| decreases)."""

    #: Base velocity limits (vx m/s, vy m/s, ωz rad/s) and acceleration limits (per s).
    v_max: Limits3 = msgspec.field(default_factory=lambda: [0.8, 0.4, 1.0])
    a_max: Limits3 = msgspec.field(default_factory=lambda: [1.0, 1.0, 2.0])
    #: Braking limits (|v| decreasing), per s: harder than speeding up, so stops are short.
    d_max: Limits3 = msgspec.field(default_factory=lambda: [2.0, 2.0, 3.0])


class EstimatorSettings(_Section):
    """The WBC's leg-inertial estimator (`services.wbc.estimator`): the tilt filter's
    gains, and the Kalman filter's noises (process: per √s; measurement: σ)."""

    tilt_kp: NonNegative = 0.1  # 1/s: how fast gravity pulls roll and pitch
    tilt_ki: NonNegative = 0.05  # 1/s²: how fast the gyro's roll and pitch bias is learnt
    #: m/s²: the accelerometer corrects the tilt only within g ± this (a push, a foot's
    #: impact). Not tight: a trot's own accelerations must average out, and a tight
    #: gate keeps a biased half of them (1 m/s² tilted the estimate 6° in 5 s of trot).
    gravity_gate: Positive = 5.0
    #: 1/s: how fast the stance feet's plane (a flat floor) pulls roll and pitch.
    floor_kp: NonNegative = 10.0
    #: rad: a pair of stance feet sloping more than this (a slip, a step) is ignored.
    floor_gate: Positive = 0.2
    calibrate_s: NonNegative = 1.0  # s standing still: the gyro's bias
    #: s of sim time the gait waits at start-up for that calibration; then it goes anyway.
    calibrate_timeout_s: NonNegative = 5.0
    q_position: NonNegative = 0.002  # m/√s
    q_accel: NonNegative = 0.5  # m/s/√s: the IMU's acceleration error
    q_foot_stance: NonNegative = 0.005  # m/√s: a stance foot's slip
    q_foot_swing: NonNegative = 2.0  # m/√s
    r_kin: Positive = 0.005  # m: the legs' kinematics
    r_vel: Positive = 0.05  # m/s: a stance foot's velocity (encoders, a foot rolling)
    r_height: Positive = 0.005  # m: a stance foot's height above the floor


class WbcSettings(_Section):
    """The whole-body controller service (`services/wbc`).

    Its rate is its lockstep participant's `period_s` (`time.participants.wbc`).
    """

    #: The mode at start-up: damp, stand, walk or manipulate.
    initial_mode: Literal["damp", "stand", "walk", "manipulate"] = "stand"
    #: SCHED_FIFO priority of the controller's threads (`common.sched`; 0: the normal
    #: scheduler). Where the OS refuses it the controller says so and runs as normal.
    realtime_priority: Annotated[int, msgspec.Meta(ge=0, le=99)] = 10
    #: The `cmd_vel` source obeyed until a `wbc/mode` names another.
    cmd_vel_source: str = "navigation"
    #: Who publishes `wbc/mode` (its participant latency applies to modes).
    mode_source: str = "mission"
    #: A cmd_vel older than this (sim time) means stop.
    cmd_vel_timeout_s: Positive = 0.5
    gait: GaitSettings = msgspec.field(default_factory=GaitSettings)
    #: Where the base's pose and twist come from: `estimate`, the leg-inertial estimator
    #: on the robot's sensors (it publishes `odom`); `truth`, the sim's free joint (an
    #: ablation: the sim publishes `odom`, and no localization runs).
    base_state: Literal["estimate", "truth"] = "estimate"
    estimator: EstimatorSettings = msgspec.field(default_factory=EstimatorSettings)
    #: A gap in the state's stamps longer than this stops the robot.
    stale_state_s: Positive = 0.05
    #: `wbc/status` rate and rerun time-series rate, Hz of sim time.
    status_hz: Positive = 50.0
    log_hz: Positive = 25.0
    #: Torque cap of Grasp goals, N·m (a goal's max_effort is clipped to it).
    grip_effort_max_nm: Positive = 5.0
    #: Good QP solves in a row before leaving the fallback stand hold.
    recover_ticks: PositiveInt = 50


class PerceptionSettings(_Section):
    """The perception service (`services/perception`); its rate is its lockstep
    participant's `period_s` (`time.participants.perception`), a multiple of the cameras'.

    segmenter: `network` (the ONNX instance segmentation network, the default) or `truth`
    (the sim's `segmentation_truth` labels: ablation and evaluation only, named so in
    every `Detections`). model: the ONNX file, relative to the repository root.
    """

    segmenter: Literal["network", "truth"] = "network"
    model: str = "services/perception/models/segmenter.onnx"
    #: Instances scored below this are dropped.
    min_score: Fraction = 0.5
    #: Cameras processed (those the sim also publishes).
    cameras: list[str] = msgspec.field(default_factory=lambda: ["camera_head", "camera_wrist"])
    #: Wall seconds to wait for a camera's frame stamped at a tick before publishing an
    #: empty `Detections` with the reason.
    frame_timeout_s: Positive = 2.0
    #: Locate by map id: a detection of the entity's class within this distance of its
    #: mapped position (m, horizontal) is that entity.
    locate_gate_m: Positive = 0.5
    #: Threads of the network's forward (`cv2.setNumThreads`). One: on a small machine the
    #: sim and the controller hold the other cores, and a forward split over threads waits
    #: for the slowest (under load, 2 threads: p50 42-56 ms, p95 88-105 ms; 1: 33-36 ms,
    #: 72-75 ms). 0 lets OpenCV choose.
    dnn_threads: NonNegativeInt = 1
    #: The can/box shape check (`services.perception.measure.ShapeCheck`): within this
    #: depth of the camera (m) a can or box whose points fit a cylinder within
    #: `shape_check_rms_per_m2` × depth² (m) is a can, else a box; 0 m: no check.
    #: Measured on the perception bench's renders (hall seeds 0-9, 9001-9003, the sim's
    #: depth noise) within 1.2 m: 61 cans fit within 1.7-2.4e-3 × depth² (the noise
    #: itself), 56 boxes no better than 3.2e-3; the network had 10 of the 117 wrong.
    #: Farther, the noise hides the shape. A real camera needs its own figure.
    shape_check_range_m: NonNegative = 1.2
    shape_check_rms_per_m2: Positive = 2.8e-3


class SemanticMapSettings(_Section):
    """The semantic map service (`services/semantic_map`).

    start: how an empty database is filled — `prior` (the map file `prior_file`),
    `seed-from-world` (the sim's truth ids at truth positions plus Gaussian noise of
    `seed_noise_m`: sim truth, for experiments), `empty` (then `dume map --patrol`, the
    mission's mapping patrol). A database that already holds a map is resumed whatever
    `start` says (ids are stable across restarts) unless `reset` is true.
    floor_plan: the static occupancy layer when the start mode brings none (`world`: the
    simulator's grid, the building's floor plan; `none`).
    site: which place the map is of (`Config.map_site`; empty: the simulated world,
    `hall seed 3`). A database, a prior map file or an import of another site is never
    used: the service refuses it with the reason. name: the database's; empty: the
    site's (`hall-seed-3`), so that each world keeps its own map.
    """

    start: Literal["prior", "seed-from-world", "empty"] = "empty"
    site: str = ""
    name: str = ""
    #: Folder of the databases (`<dir>/<name>.sqlite`), relative to the repository root.
    dir: str = "var/map"
    #: True: start over whatever the database holds.
    reset: bool = False
    prior_file: str = ""
    seed_noise_m: NonNegative = 0.05
    seed_noise_seed: NonNegativeInt = 0
    floor_plan: Literal["world", "none"] = "world"
    #: Cameras whose detections are fused: the head camera. The wrist camera, away from a
    #: table, sees the robot's own legs and the floor at close range (false people); the
    #: mission reads its close-up views itself.
    cameras: list[str] = msgspec.field(default_factory=lambda: ["camera_head"])
    #: Measurement noise of a detection's horizontal position: sigma0 + per_m × range, m.
    sigma0_m: NonNegative = 0.02
    sigma_per_m: NonNegative = 0.02
    #: Association gate: a detection joins an entity of its class within
    #: max(gate_min_m, gate_sigmas × combined σ).
    gate_min_m: Positive = 0.25
    gate_sigmas: Positive = 3.0
    #: Detections an artifact or person needs before it gets an id.
    confirm_hits: PositiveInt = 2
    #: One object in pieces: detections of one class in one frame, and artifacts of one
    #: class, closer than `class_merge_m` are one (the thinnest two touching stand 4 cm
    #: apart). One object under two classes: artifacts closer than `class_merge_m` are
    #: one, and the class seen more often from within `class_near_m` keeps it, m. One never
    #: seen whole from within `class_near_m` is the same object within `class_merge_far_m`
    #: (far views sit 10-16 cm off; a second real object there would have been seen from
    #: where the other was: hall seed 1's ghost can was 6 cm from the box it misread).
    class_near_m: Positive = 2.0
    class_merge_m: NonNegative = 0.05
    class_merge_far_m: NonNegative = 0.2
    #: Below this score a detection is ignored.
    min_score: Fraction = 0.5
    #: Frames looking at an artifact's place without seeing it before it is missing.
    missing_after_frames: PositiveInt = 5
    #: Range within which a camera is trusted to see an artifact, and a person, m (the
    #: network finds a can on a bench from the wrist camera at 2 m, not at 2.5 m: a look
    #: from farther proves nothing; the head camera's looks from 2-3 m deleted the small
    #: world's true bottle twice in a patrol).
    look_range_m: Positive = 2.0
    person_look_range_m: Positive = 6.0
    #: A person detection this close to a static obstacle cell is not a person, m.
    person_obstacle_margin_m: NonNegative = 0.1
    #: An artifact or person the map created itself from perception and fused fewer times
    #: than this, or an artifact it saw only from beyond `class_near_m`, is a false entry
    #: when looked for at its place and not seen: it is deleted (prior, seeded and
    #: imported artifacts are only marked missing). 0: no entry is ever deleted.
    drop_below_observations: NonNegativeInt = 10
    #: People: acceleration noise of the constant-velocity model, m/s², and the weight of
    #: the colour-histogram distance in the association cost.
    person_accel_sigma: Positive = 1.5
    appearance_weight: NonNegative = 4.0
    #: Learned obstacles: frames a cell must be seen occupied in, heights counted, m.
    obstacle_hits: PositiveInt = 3
    #: On a static layer the robot sensed (its SLAM grid, a saved map), the frames a cell
    #: must be seen in, and how far from the lidar's obstacles (walls, machines: not a
    #: table's legs) the depth learns none, m: the pose's error paints a wall's face 10-25
    #: cm in front of it from far away, and the lidar has that face already (the explored
    #: small world: the learned layer's false cells 930 → 10, the map's IoU 0.66 → 0.92).
    obstacle_hits_sensed: PositiveInt = 12
    sensed_clearance_m: NonNegative = 0.2
    obstacle_z_m: tuple[FiniteFloat, FiniteFloat] = (0.15, 1.9)
    #: Grid extent when no floor plan gives one (a square about the origin), m.
    grid_half_extent_m: Positive = 15.0
    grid_resolution_m: Positive = 0.05
    #: Cameras also fused while the mission's patrol holds the arm in `look` (its
    #: `mission/patrol/status` says so).
    patrol_cameras: list[str] = msgspec.field(default_factory=lambda: ["camera_wrist"])
    #: Sim seconds between rerun logs of the entities and of the grid.
    log_every_s: Positive = 1.0
    grid_log_every_s: Positive = 5.0
    #: A file (relative to the repository root) the people tracker's input is written to,
    #: frame by frame, for replay (`services/semantic_map/people_trace.py`, `dume bench
    #: people-ids`); empty: none.
    people_trace: str = ""


class ControllerSettings(_Section):
    """Navigation's path follower (`services/navigation/controller.py`): pure pursuit."""

    #: Base velocity limits (vx m/s, vy m/s, ωz rad/s) and acceleration limits (per s).
    v_max: Limits3 = msgspec.field(default_factory=lambda: [0.5, 0.3, 0.8])
    a_max: Limits3 = msgspec.field(default_factory=lambda: [0.8, 0.8, 1.5])
    #: How far along the path the point pursued lies, m.
    lookahead_m: Positive = 0.6


class PlannerSettings(_Section):
    """Navigation's global planner (`services/navigation/planner.py`, A* on the costmap)."""

    #: How many metres one metre at cost 1 is worth, on top of itself (an edge costs
    #: length · (1 + cost_weight · cost)).
    cost_weight: NonNegative = 4.0
    #: How far a goal in an obstacle may move to the nearest free pose (same yaw), m.
    goal_search_m: NonNegative = 0.5


class PeopleSettings(_Section):
    """Navigation's speed rules around people (`services/navigation/people.py`).

    Distances m from the robot's footprint, speeds m/s, times s. The slow zone: the cap
    within `slow_radius_m` of anyone (`slow_speed`) or of the person handed over to
    (`handover_speed`). The protective separation of ISO/TS 15066
    (`services/navigation/separation.py`): the reaction time from a camera frame to a
    command in effect (the head camera's period, perception's and navigation's), the
    deceleration the trot brakes at, the intrusion distance C (a body's reach beyond the
    point perception measures), the uncertainties of the person's position Z_d and of the
    robot's Z_r, the margin on a person's estimated speed, and the speed assumed for a
    person whose velocity is not known yet (ISO 13855's walking speed). The monitor
    keeps the separation `monitor_lead_s` ahead of now (S_p with T_r + lead: the
    protective distance of the moment its command takes effect, so that the standard's
    S_p still holds then: a judge from truth checks every instant, the monitor acts once
    a tick; not in the judge's own S_p). A goal blocked
    with a person within `slow_radius_m` of the footprint or of the goal waits `wait_s`
    longer before its recoveries (people move on; backing into them does not help).
    """

    slow_radius_m: NonNegative = 2.0
    wait_s: NonNegative = 20.0
    slow_speed: NonNegative = 0.3
    handover_speed: NonNegative = 0.15
    reaction_s: NonNegative = 0.3
    brake_decel_mps2: Positive = 0.5
    intrusion_m: NonNegative = 0.25
    detection_uncertainty_m: NonNegative = 0.1
    robot_uncertainty_m: NonNegative = 0.05
    person_speed_margin_mps: NonNegative = 0.3
    unknown_person_speed_mps: NonNegative = 1.6
    monitor_lead_s: NonNegative = 0.4


class NavigationSettings(_Section):
    """The navigation service (`services/navigation`); its rate is its lockstep
    participant's `period_s` (`time.participants.navigation`).

    map_source: `map` (the semantic map's queryables) or `world` (the sim's truth
    description: occupancy, artifacts, people — for tests and development only).
    Speeds m/s, distances m (people distances from the footprint), times s of sim time.
    """

    map_source: Literal["map", "world"] = "map"
    #: The depth camera of the short-lived obstacle layer ("" for none), and how long a
    #: cell it saw occupied stays so.
    obstacle_camera: str = "camera_head"
    obstacle_ttl_s: Positive = 3.0
    controller: ControllerSettings = msgspec.field(default_factory=ControllerSettings)
    planner: PlannerSettings = msgspec.field(default_factory=PlannerSettings)
    #: Arrival tolerances of the standoff and handover goals (a PoseGoal carries its own).
    goal_tolerance_m: Positive = 0.08
    goal_tolerance_rad: Positive = 0.1
    people: PeopleSettings = msgspec.field(default_factory=PeopleSettings)
    #: People in the costmap: plans go around them (off: only the speed rules act).
    people_in_costmap: bool = True
    #: A goal: replanned every `replan_s`; blocked (no plan, or no progress) this long
    #: starts the next recovery, and after the last fails it; `goal_timeout_s` fails it.
    replan_s: Positive = 1.0
    blocked_timeout_s: Positive = 3.0
    goal_timeout_s: Positive = 180.0
    #: How often the semantic map's occupancy and people are fetched (map source), s.
    map_refresh_s: Positive = 1.0


class ApproachSettings(_Section):
    """The mission's visual approach (`services/mission/approach.py`, eq. 3): gains (1/s),
    limits (m/s, rad/s, m/s², rad/s²), tolerances (m, rad), times (s of sim time). The
    optimum (d_opt, θ_opt) is the robot's (`common.robot.D_OPT_M`, `THETA_OPT_RAD`)."""

    #: vx per m of distance error, ωz per rad of heading error.
    k_d: Positive = 0.8
    k_theta: Positive = 1.2
    vx_max: Positive = 0.25
    wz_max: Positive = 0.5
    ax_max: Positive = 0.5
    az_max: Positive = 1.0
    tol_d_m: Positive = 0.03
    tol_theta_rad: Positive = 0.05
    #: Both errors within tolerance this long: arrived.
    settle_s: Positive = 0.6
    #: Blocked short of d_opt (the legs stopped short of the support's front): arrived when
    #: the distance error is at most `blocked_slack_m` and no sighting came `progress_m`
    #: nearer for `stall_s`. 0.17 m: what a hip pressed against the front reached before
    #: the base stopped 5 cm short of it (an object 0.4 m deep on a bench).
    blocked_slack_m: Positive = 0.17
    progress_m: Positive = 0.01
    stall_s: Positive = 4.0
    #: A sighting older than this no longer drives the base; none this long: re-acquire.
    max_age_s: Positive = 0.35
    lost_after_s: Positive = 1.0
    #: Re-acquiring this long without a sighting: failed.
    reacquire_s: Positive = 5.0
    #: Turn rate toward the last seen bearing, and how far past its error to turn.
    reacquire_wz: Positive = 0.3
    reacquire_turn_margin_rad: Positive = 0.15
    #: Backwards speed while re-acquiring, and the distance after which backing off stops.
    back_off_speed: Positive = 0.08
    back_off_max_m: NonNegative = 0.3
    #: No arrival this long after the approach starts: failed.
    timeout_s: Positive = 40.0

    def __post_init__(self) -> None:
        positive = {
            k: getattr(self, k)
            for k in self.__struct_fields__
            if k not in ("back_off_speed", "back_off_max_m")
        }
        bad = {k: v for k, v in positive.items() if not (math.isfinite(v) and v > 0.0)}
        if bad:
            raise ValueError(f"approach gains must be finite and positive: {bad}")
        if not (self.max_age_s < self.lost_after_s):
            raise ValueError(
                f"max_age_s ({self.max_age_s}) must be shorter than lost_after_s "
                f"({self.lost_after_s})"
            )


class PullSettings(_Section):
    """The felt handover (`services/mission/handover_feel.py`): the pull along the
    direction to the person that trips it (N), the jaw effort change that counts with
    half of it (N·m), how long it must hold (s of sim time), the baseline's averaging
    time (s), and the absolute force that trips it alone (N)."""

    #: A person's pull reaches 15-17 N within 0.4 s of their grip closing; before it,
    #: the arm's estimate swings by up to 4 N toward them for 0.2 s (hall seed 5's
    #: reaching hand knocked the can; `dume trial fetch --world hall --world-seed 5`).
    force_n: Positive = 8.0
    effort_nm: Positive = 0.5
    debounce_s: Positive = 0.2
    baseline_s: NonNegative = 0.3
    absolute_n: Positive = 8.0


class MissionSettings(_Section):
    """The mission service (`services/mission`); its rate is its lockstep participant's
    `period_s` (`time.participants.mission`). Times are s of sim time unless named wall.

    The visual approach's gains are `approach_gains` (`ApproachSettings`), the felt
    handover's thresholds `pull_detector` (`PullSettings`).
    """

    #: A status goes out on every change and at least this often.
    status_every_s: Positive = 1.0
    #: Wall seconds a query may take (map, nav goal, arm goal) before it counts as no answer.
    query_timeout_s: Positive = 2.0
    #: Wall seconds to wait for the odom stamped at a tick before ticking without it.
    input_timeout_s: Positive = 30.0
    #: The whole-body controller must report a requested mode within this.
    mode_timeout_s: Positive = 2.0
    #: A navigation goal that reports no status this long after it was sent fails.
    nav_status_timeout_s: Positive = 5.0
    #: Arm goals: how long each may stay active before it counts as failed.
    posture_timeout_s: Positive = 12.0
    reach_timeout_s: Positive = 20.0
    #: A grasp's Reach that gives up farther than this from its goal met something solid
    #: or is out of reach: `grasp_pose_failed`, not re-picked (m).
    reach_miss_max_m: Positive = 0.06
    grasp_timeout_s: Positive = 8.0
    release_timeout_s: Positive = 5.0
    #: A Reach or Posture sent with a mapped person within `arm_slow_m` of the base (m;
    #: 0: never) moves at `arm_slow_speed` of the arm's speeds: the handover's (its person
    #: 1.3 m off) and any near a bystander.
    arm_slow_m: NonNegative = 1.6
    arm_slow_speed: Annotated[float, msgspec.Meta(gt=0.0, le=1.0)] = 0.5
    #: After the grasp, the object is lifted this far straight up before stowing, m.
    lift_m: NonNegative = 0.10
    #: Put back where it was picked, the object is let go this far above its old place
    #: (the grasp pose raised this much), m.
    put_down_clear_m: NonNegative = 0.015
    #: The whole visual approach (the controller re-acquires and fails by itself sooner),
    #: not counting the time its commands were held back for people (the speed and
    #: separation monitor's caps), which is bounded on its own: a person who stays in the
    #: way is waited for `approach_held_max_s` in all, then the approach fails
    #: `blocked_by_person`.
    approach_timeout_s: Positive = 90.0
    approach_held_max_s: Positive = 120.0
    #: Pose estimation: stand still this long, then wait this long for a detection.
    settle_s: NonNegative = 0.5
    detection_timeout_s: Positive = 3.0
    #: Wrist detections older than this (sim time, behind the tick) are not a sighting.
    sighting_max_age_s: Positive = 0.5
    #: A wrist detection is the target only this close to its mapped place, m.
    sighting_gate_m: Positive = 0.35
    #: The handover: how long to wait for the pull; the back-off after the release.
    handover_timeout_s: Positive = 60.0
    #: A person whose facing the map does not know (one it saw, not seeded from truth):
    #: the sides tried round them (the first the robot's, then 60° either way, 120°,
    #: 180°: a person takes what is held out within 33° of their front) and the wait for
    #: the pull on each, s.
    handover_sides: PositiveInt = 6
    handover_side_timeout_s: Positive = 10.0
    #: Nobody pulling this long at an offer, the robot holds the object out this much
    #: nearer (once an offer: `handover.LeanIn`; the person's hand takes what is held out
    #: within 0.25 m of it, and the base stands a few centimetres off its pose), s and m.
    handover_lean_after_s: Positive = 8.0
    handover_lean_m: NonNegative = 0.08
    #: The object leaving the jaws this soon after a pull was felt was taken, not lost (s).
    handover_taken_window_s: NonNegative = 0.5
    #: At the handover pose: look this long, then walk again if the person's mapped place
    #: is farther than this from straight ahead at the handover distance (m).
    handover_check_s: NonNegative = 1.0
    handover_tol_m: Positive = 0.12
    #: A person not seen at the handover pose: after a turn round on the spot, stand this
    #: long asking for them ("asking for <person>: please come to the robot") before
    #: walking to one of their usual places, or to where the map last had them: a person
    #: 8 m off who hears it walks over in 10 s and stands (`ANSWER_STAND_S`) in 15.
    person_ask_s: NonNegative = 20.0
    #: A person not at the handover pose: the rounds of looking for them (at their usual
    #: places) and walking to them again before the request fails `person_not_found`.
    person_rounds: PositiveInt = 6
    #: After the release: walk backwards at this speed (m/s) for this long.
    back_off_speed: Positive = 0.15
    back_off_s: NonNegative = 1.0
    #: Recovery: re-picks after a grasp lost or failed; instances tried for a class request.
    repick_budget: NonNegativeInt = 2
    max_candidates: PositiveInt = 3
    #: An object found at none of its candidates' places is looked for elsewhere once
    #: (`services/mission/search.py`): at most `search_places` places (its last, where
    #: its class was seen within `search_recent_s`, the supports nearest first); 0: never.
    search_places: NonNegativeInt = 6
    search_recent_s: Positive = 600.0
    approach_gains: ApproachSettings = msgspec.field(default_factory=ApproachSettings)
    pull_detector: PullSettings = msgspec.field(default_factory=PullSettings)
    #: The mapping patrol (`dume map --patrol`): viewpoint spacing and the clearance kept
    #: from obstacles, m; a look-around (three turns on the spot) at every viewpoint.
    patrol_spacing_m: Positive = 2.5
    patrol_clearance_m: NonNegative = 0.7
    patrol_look_around: bool = True
    #: The floor plan's tables and benches are seen from a viewpoint within this, m (the
    #: network finds a can on a bench from 2 m with the arm in `look`).
    patrol_see_m: NonNegative = 1.6
    #: The semantic pass after an exploration looks at each surface from no nearer than
    #: this (m): nearer, the wrist camera sees a strip of the top.
    patrol_near_m: NonNegative = 0.8
    #: After the semantic pass, a second look from within `patrol_recheck_see_m` at each
    #: artifact in doubt: one the map saw only from beyond `patrol_recheck_beyond_m` (the
    #: map's `class_near_m`: its class is a guess), or one closer than
    #: `patrol_recheck_pair_m` to another class's (one object read two ways: two real
    #: ones stand 0.3 m apart or more), or one seen fewer than `patrol_recheck_below`
    #: times (the map's `drop_below_observations`: a look that misses it deletes it; hall
    #: seed 2 kept a box seen twice from 1.7 m that no later look came near).
    patrol_second_look: bool = True
    patrol_recheck_beyond_m: Positive = 2.0
    patrol_recheck_below: NonNegativeInt = 10
    patrol_recheck_pair_m: NonNegative = 0.25
    patrol_recheck_see_m: Positive = 1.3
    #: At each viewpoint of a route that faces what it came for (the semantic pass, the
    #: second look) the patrol holds this long before it walks on or ends, s: the map
    #: counts an artifact missing after `missing_after_frames` looks at its place, and the
    #: second look's last viewpoint ended the route as it arrived (hall seed 4's box_3,
    #: a bench's end read as a box, was looked at again and kept).
    patrol_dwell_s: NonNegative = 1.0
    #: The arm's posture while patrolling: `look` holds the wrist camera up (about 1.1 m,
    #: looking ahead and down) where it sees the tops of benches that the head camera,
    #: pitched 20° down under the trunk, cannot see within 2.5 m; `stow` leaves it folded.
    patrol_arm_posture: Literal["look", "stow"] = "look"
    #: Exploration from nothing (`dume map --explore`, a request `{"task": "explore"}`):
    #: frontier after frontier (`services/mission/frontiers.py`) until none is reachable.
    #: A frontier shorter than `explore_min_frontier_m` is none (about the robot's width:
    #: on the SLAM's lidar map, gaps of 0.3 m at walls drew 4-5 m walks); a goal keeps
    #: `explore_clearance_m` from every occupied or unknown cell (the footprint turning on
    #: the spot: its circumscribed radius is 0.67 m) and looks at its frontier from 1-2 m;
    #: its cost is the path less `explore_gain` × the frontier in sight (m per m); a goal
    #: that failed or was looked around from bars others within `explore_blacklist_m`, and
    #: what a look-around left unseen within `explore_seen_m` of it is no frontier (m).
    explore_min_frontier_m: Positive = 0.5
    explore_clearance_m: Positive = 0.7
    explore_gain: NonNegative = 0.5
    explore_blacklist_m: NonNegative = 0.75
    explore_seen_m: NonNegative = 1.2
    #: Frontiers farther than this from where the exploration started are left (m; 0:
    #: none is, the map's grid bounds it): a hall's doors open on floor that goes on.
    explore_radius_m: NonNegative = 0.0
    #: The site's outline, as the operator gives it: frontiers outside the rectangle
    #: (x0, y0, x1, y1 m in the map's frame) are left. None: the map's grid bounds it.
    explore_bounds: tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat] | None = None
    #: The exploration's budget: goals chosen, and sim seconds; spent while a reachable
    #: frontier is left, it fails `budget`.
    explore_max_goals: PositiveInt = 60
    explore_max_s: Positive = 1800.0
    #: It is done when the last `explore_stall_goals` goals together added less than
    #: `explore_stall_m2` of known floor, frontiers left or not (0 goals: only when no
    #: reachable frontier is left). A hall's exploration has flat stretches of 3-5 goals
    #: between big gains (a corner cleaned up, then a new aisle): the window is long.
    explore_stall_goals: NonNegativeInt = 12
    explore_stall_m2: NonNegative = 2.0
    #: The arm while exploring: the head camera maps the floor (`look` would let the map
    #: fuse the wrist camera too).
    explore_arm_posture: Literal["look", "stow"] = "stow"
    #: After an exploration that succeeded, walk the patrol's coverage route over the
    #: explored map (the semantic pass: the arm in `patrol_arm_posture`).
    explore_semantic_pass: bool = False


class RecordingSettings(_Section):
    enabled: bool = True
    #: Recordings go to `<dir>/<run id>/<service>.rrd`: by default the run's folder, beside
    #: its logs (`deploy.runs`).
    dir: str = "var/run"
    #: One id shared by every service of a run; `dume up` sets a fresh one.
    run_id: str = ""
    #: gRPC address of a live viewer (`rerun+http://127.0.0.1:9876/proxy`), empty for none.
    viewer: str = ""
    #: Log every n-th camera frame, by its stamp (images dominate the recording's size).
    camera_every: PositiveInt = 2
    #: Of the logged frames, log depth and segmentation with every n-th (they do not
    #: compress like RGB's JPEG).
    depth_every: PositiveInt = 10
    #: Wall seconds the recording batches rows before writing them: fewer, larger chunks
    #: (a chunk per entity per flush, each with its ~2 KB schema: at rerun's 0.2 s they
    #: were most of the file); a live viewer lags by as much.
    flush_s: Positive = 5.0


class CpuSettings(_Section):
    """Which CPUs each process may run on (`common.sched.CpuLayout`; Linux only).

    `split`: the lockstep chain's hot half, the processes in `control` (the sim's
    physics and the WBC alternate every command period, through the router), on CPU 0;
    everything else (the sim's render thread, perception, the map, navigation, the
    mission) on the others. The chain's tick then finds its caches warm instead of
    evicted by rendering and the network (`dume bench stack`, 2 cores: the WBC's tick
    p99 0.66 → 0.40 ms, the real-time factor 1.25 → 1.5). `any`: the OS places every
    thread. One CPU always means `any`. Stacks side by side on one machine would all
    share CPU 0: give them `any`.
    """

    layout: Literal["split", "any"] = "split"
    control: tuple[str, ...] = ("sim", "wbc", "router")


class SlamSettings(_Section):
    """Mapping while localizing (`services/localization/slam.py`), when the map has no
    static layer to localize on. Distances m, angles rad, the grid's geometry that of the
    map's (`semantic_map.grid_*`)."""

    #: A pose this far from the last keyframe (m, rad) makes a new one.
    keyframe_m: Positive = 0.4
    keyframe_rad: Positive = 0.26
    #: The local map the scans are tracked on: the last n keyframes' returns.
    local_keyframes: PositiveInt = 20
    #: A local match is taken when this share of its beams ends on the local map.
    min_inliers: Unit = 0.4
    #: How far a scan's match may stray from the odometry's prediction at no cost (1 σ of
    #: the prior the match weighs against its beams), m and rad.
    prior_sigma_m: Positive = 0.02
    prior_sigma_rad: Positive = 0.01
    #: The between factors' noise: a floor and a share per metre between keyframes.
    odom_sigma_m: Positive = 0.01
    odom_sigma_per_m: NonNegative = 0.02
    odom_sigma_rad: Positive = 0.003
    odom_sigma_rad_per_m: NonNegative = 0.01
    #: Loop closures: a new keyframe within `closure_radius_m` of one `closure_gap` or
    #: more keyframes older, tried every `closure_every` keyframes, on a submap of the
    #: older one and `closure_submap` neighbours each side, searched ± m and ± rad around
    #: the graph's pose, taken at `closure_min_inliers`.
    closure_radius_m: Positive = 2.5
    closure_gap: PositiveInt = 25
    closure_every: PositiveInt = 3
    closure_submap: NonNegativeInt = 5
    closure_search_m: Positive = 0.4
    closure_search_rad: Positive = 0.12
    closure_min_inliers: Unit = 0.6
    #: How a closure registers the new scan on the older submap: `field` (a correlative
    #: search, then the Gauss-Newton refine, on the submap's grid) or `gicp` (small_gicp's
    #: GICP on the submap's returns); `dume bench slam` measures both.
    closure_registration: Literal["field", "gicp"] = "gicp"
    closure_sigma_m: Positive = 0.03
    closure_sigma_rad: Positive = 0.01
    #: The grid: a cell is occupied when this share of the beams that met it ended there.
    occupied_ratio: Unit = 0.4
    half_extent_m: Positive = 15.0
    resolution_m: Positive = 0.05
    #: The local map's cells, m: finer than the map's, so a scan's heading is not
    #: quantised to what a 5 cm cell 5 m away allows (0.4°).
    track_resolution_m: Positive = 0.025
    #: The grid goes out on `slam/occupancy` at most this often, s of sim time.
    publish_every_s: Positive = 1.0


class LocalizationSettings(_Section):
    """Where the robot is in the map.

    start_pose: where the robot stands at start-up, (x m, y m, yaw rad) in the map, as
    the user gives it (`dume up --start-pose`): the odometry starts there. Unset, the
    launcher fills in the world's start (`deploy.stack`); a service started by hand
    without it starts odometry at the origin.
    """

    start_pose: tuple[FiniteFloat, FiniteFloat, FiniteFloat] | None = None
    #: Every n-th beam of a scan is matched (541 → 181).
    beam_stride: PositiveInt = 3
    #: A match is taken when this share of its beams ends within `inlier_m` of the map.
    min_inliers: Unit = 0.5
    inlier_m: Positive = 0.1
    #: Beyond this a beam's end pulls no harder (people, clutter the map lacks), m.
    huber_m: Positive = 0.1
    #: A match farther than this from the odometry's prediction is refused, m and rad.
    gate_m: Positive = 0.15
    gate_rad: Positive = 0.1
    #: So many refused scans in a row: lost (navigation stops); a search window then
    #: re-seeds the match, as at start-up: ± m and ± rad.
    lost_after: PositiveInt = 10
    search_m: Positive = 0.6
    search_rad: Positive = 0.27
    #: How the covariance grows while no scan matches: m² of x, y and rad² of yaw per m
    #: the odometry travelled.
    growth_per_m: NonNegative = 0.01
    #: `localize` on the map's static layer, `slam` (build the map while localizing on
    #: it), or `auto`: slam when the map has no static layer (an empty map: exploring).
    mode: Literal["auto", "localize", "slam"] = "auto"
    slam: SlamSettings = msgspec.field(default_factory=SlamSettings)


class LogSettings(_Section):
    level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    #: Log, every `trace_every_s` of sim time, a running digest of everything each
    #: publisher sent (`common.bus.Publisher`): two runs of one seed that differ show in
    #: the first service and key whose lines differ. 0: off.
    trace_every_s: NonNegative = 0.0


class Config(_Section):
    robot: str = "b1"
    zenoh: ZenohSettings = msgspec.field(default_factory=ZenohSettings)
    time: TimeSettings = msgspec.field(default_factory=TimeSettings)
    sim: SimSettings = msgspec.field(default_factory=SimSettings)
    wbc: WbcSettings = msgspec.field(default_factory=WbcSettings)
    perception: PerceptionSettings = msgspec.field(default_factory=PerceptionSettings)
    navigation: NavigationSettings = msgspec.field(default_factory=NavigationSettings)
    semantic_map: SemanticMapSettings = msgspec.field(default_factory=SemanticMapSettings)
    mission: MissionSettings = msgspec.field(default_factory=MissionSettings)
    recording: RecordingSettings = msgspec.field(default_factory=RecordingSettings)
    localization: LocalizationSettings = msgspec.field(default_factory=LocalizationSettings)
    cpu: CpuSettings = msgspec.field(default_factory=CpuSettings)
    log: LogSettings = msgspec.field(default_factory=LogSettings)

    def map_site(self) -> str:
        """The place this stack's map is of: `semantic_map.site`, else the simulated
        world (`hall seed 3`)."""
        return self.semantic_map.site or f"{self.sim.world} seed {self.sim.world_seed}"

    def odom_from_estimate(self) -> bool:
        """Whether `odom` is the WBC's estimate (`wbc.base_state = "estimate"`, on legs,
        with the WBC the stack's commander); otherwise the sim publishes its free joint
        (the truth ablation; kinematic locomotion, where the base is moved, not walked;
        a stack without the WBC, such as the stand-hold commander's)."""
        return (
            self.wbc.base_state == "estimate"
            and self.sim.locomotion == "dynamic"
            and "wbc" in self.time.participants
        )


def _literal(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _set_path(tree: dict[str, Any], path: Sequence[str], value: Any) -> None:
    node = tree
    for part in path[:-1]:
        child = node.setdefault(part, {})
        if not isinstance(child, dict):
            raise ConfigError(f"{'.'.join(path)}: {part!r} is a value, not a section")
        node = child
    node[path[-1]] = value


def _env_overrides(env: Mapping[str, str]) -> list[tuple[list[str], Any]]:
    sections = sorted((f for f in Config.__struct_fields__ if f != "robot"), key=len, reverse=True)
    out: list[tuple[list[str], Any]] = []
    for name, text in sorted(env.items()):
        not_a_setting = name in ENV_NOT_SETTINGS or name.startswith(ENV_START)
        if not name.startswith(ENV_PREFIX) or not_a_setting:
            continue
        rest = name[len(ENV_PREFIX) :].lower()
        if rest == "robot":
            out.append((["robot"], text))
            continue
        section = next((s for s in sections if rest.startswith(s + "_")), None)
        if section is None:
            raise ConfigError(
                f"environment variable {name}: no section {rest.split('_')[0]!r}; "
                f"sections are {sorted(sections)} (or DUME_ROBOT)"
            )
        out.append((_env_path(section, rest[len(section) + 1 :]), _literal(text)))
    return out


def _env_path(section: str, key: str) -> list[str]:
    """A variable's key in `section` as a path: a nested section's name and `_` descend
    into it (`DUME_NAVIGATION_CONTROLLER_V_MAX` → navigation.controller.v_max)."""
    path = [section]
    fields = _fields(_fields(msgspec.inspect.type_info(Config))[section])
    while key not in fields:
        sub = next((f for f in fields if key.startswith(f + "_") and _fields(fields[f])), None)
        if sub is None:
            break
        path.append(sub)
        key, fields = key[len(sub) + 1 :], _fields(fields[sub])
    return [*path, key]


def _fields(node: msgspec.inspect.Type) -> dict[str, msgspec.inspect.Type]:
    """A Struct's fields by name (none for any other type)."""
    if not isinstance(node, msgspec.inspect.StructType):
        return {}
    return {f.name: f.type for f in node.fields}


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """`section.key=value` flags as data (values parsed as TOML literals), in order."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"override {item!r} is not of the form section.key=value")
        out.pop(key.strip(), None)  # a later flag wins, and keeps its place in the order
        out[key.strip()] = _literal(text.strip())
    return out


def merged(*layers: Overrides) -> dict[str, Any]:
    """Overrides one after the other (a later key wins, and applies after the earlier)."""
    out: dict[str, Any] = {}
    for layer in layers:
        for key, value in layer.items():
            out.pop(key, None)
            out[key] = value
    return out


def load_config(
    overrides: Overrides | Sequence[str] = (),
    *,
    path: str | Path | None = None,
    env: Mapping[str, str] | None = None,
) -> Config:
    """Defaults from the Structs, then the file, the environment, the run's settings file
    (`DUME_SETTINGS`), then `overrides` (data, or `section.key=value` flags)."""
    env = os.environ if env is None else env
    if not isinstance(overrides, Mapping):
        overrides = parse_overrides(overrides)
    file = Path(path or env.get("DUME_CONFIG") or DEFAULT_CONFIG)
    try:
        tree: dict[str, Any] = tomllib.loads(file.read_text())
    except FileNotFoundError:
        raise ConfigError(f"config file {file} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {file}: {exc}") from None
    for keys, value in _env_overrides(env):
        _set_path(tree, keys, value)
    for key, value in [*_settings_file(env).items(), *overrides.items()]:
        _set_path(tree, key.split("."), value)
    try:
        config = msgspec.convert(tree, Config, strict=False)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"configuration ({file} + environment + flags): {exc}") from None
    _check(config)
    return config


def _settings_file(env: Mapping[str, str]) -> dict[str, Any]:
    """The run's overrides as data (`DUME_SETTINGS`: a JSON object), or none."""
    name = env.get("DUME_SETTINGS", "")
    if not name:
        return {}
    try:
        data = msgspec.json.decode(Path(name).read_bytes(), type=dict[str, Any])
    except (OSError, msgspec.DecodeError) as exc:
        raise ConfigError(f"DUME_SETTINGS={name}: {exc}") from None
    return data


def write_settings(path: Path, overrides: Overrides) -> None:
    """Write overrides as the run's settings file (`DUME_SETTINGS`), in order."""
    path.write_bytes(msgspec.json.encode(dict(overrides)))


def _check(config: Config) -> None:
    """What a setting's type cannot say: periods in whole ticks."""
    tick = 1.0 / config.time.tick_hz
    for name, p in config.time.participants.items():
        if p.period_s < tick - 1e-12:
            raise ConfigError(
                f"time.participants.{name}: period_s {p.period_s} must be ≥ one tick ({tick})"
            )
        ticks = p.period_s * config.time.tick_hz
        if abs(ticks - round(ticks)) > 1e-6:
            raise ConfigError(f"time.participants.{name}.period_s must be whole ticks")


def resolve(path: str) -> Path:
    """A path from the config, relative to the repository root unless absolute."""
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p
