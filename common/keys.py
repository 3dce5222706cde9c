"""Every Zenoh key expression dume uses, built from one robot namespace.

Three namespaces: `dume/<robot>/…` for what belongs to one robot, `dume/map/…` for the
shared semantic map and `dume/world/…` for the simulator's world. Everything under
`dume/world/` (the clock aside) and every `*_truth` key is simulator truth
(`is_truth_key`): only the sim, tests, evaluation and options named as ablations or as
the floor-plan prior may read it; `common.truth` enforces it in every service's bus.

Nothing else in dume spells a key: services build them here, so a renamed key is one edit.
"""

from __future__ import annotations

from dataclasses import dataclass

ROOT = "dume"
DEFAULT_ROBOT = "b1"
CAMERAS = ("camera_head", "camera_wrist")
SERVICES = ("sim", "perception", "semantic_map", "navigation", "wbc", "localization", "mission")

# The shared world (sim truth) and the shared map.
WORLD_CLOCK = f"{ROOT}/world/clock"
WORLD_DESCRIPTION = f"{ROOT}/world/description"
WORLD_EVENTS = f"{ROOT}/world/events"
#: A push on the robot's base (`sim.Push`): tests and evaluation publish, the sim applies.
WORLD_PUSH = f"{ROOT}/world/push"
#: Move a person (`sim.PersonCommand`): tests and evaluation publish, the sim applies.
WORLD_PEOPLE_COMMAND = f"{ROOT}/world/people_command"
#: Where the people are (`sim.PeopleTruth`, truth): the sim publishes, evaluation reads.
WORLD_PEOPLE = f"{ROOT}/world/people"
#: Move an artifact (`sim.ArtifactCommand`): tests and evaluation publish, the sim applies.
WORLD_ARTIFACT_COMMAND = f"{ROOT}/world/artifact_command"
#: Leave a movable in the hall (`sim.MovableCommand`): tests and evaluation publish, the sim
#: applies.
WORLD_MOVABLE_COMMAND = f"{ROOT}/world/movable_command"
#: Queryable: where every artifact is now (`sim.ArtifactsTruth`, truth): tests and evaluation.
WORLD_ARTIFACTS = f"{ROOT}/world/artifacts"
MAP_ARTIFACTS = f"{ROOT}/map/artifacts"
MAP_PEOPLE = f"{ROOT}/map/people"
MAP_OCCUPANCY = f"{ROOT}/map/occupancy"
#: Queryable: the floor plan's tables and benches (`SupportListing`), what a patrol must see.
MAP_SUPPORTS = f"{ROOT}/map/supports"
#: Queryables: the whole map as a `MapFile` (export), and a `MapFile` to load (import).
MAP_EXPORT = f"{ROOT}/map/export"
MAP_IMPORT = f"{ROOT}/map/import"
#: The listings `dume/map/artifacts`, `dume/map/people` are the two keys above; one entity
#: is `dume/map/<kind>/<id>` and the servers answer `dume/map/<kind>/*`.
MAP_ARTIFACTS_ONE = f"{MAP_ARTIFACTS}/*"
MAP_PEOPLE_ONE = f"{MAP_PEOPLE}/*"
ALIVE = f"{ROOT}/alive"


def _check_chunk(value: str, what: str) -> str:
    bad = set("/*$?#") & set(value)
    if not value or bad:
        raise ValueError(f"{what} {value!r} must be a non-empty key chunk without {'/*$?#'}")
    return value


def map_artifact(artifact_id: str) -> str:
    """`dume/map/artifacts/<id>`: one artifact of the semantic map (queryable)."""
    return f"{MAP_ARTIFACTS}/{_check_chunk(artifact_id, 'artifact id')}"


def map_person(person_id: str) -> str:
    """`dume/map/people/<id>`: one person of the semantic map (queryable)."""
    return f"{MAP_PEOPLE}/{_check_chunk(person_id, 'person id')}"


def is_truth_key(key: str) -> bool:
    """Whether `key` carries simulator truth: `dume/world/…` but the clock, or a segment
    ending in `_truth` (`state_truth`, `segmentation_truth`)."""
    if key == WORLD_CLOCK:
        return False
    return key.startswith(f"{ROOT}/world/") or any(p.endswith("_truth") for p in key.split("/"))


@dataclass(frozen=True)
class RobotKeys:
    """The keys of one robot, `dume/<robot>/…` (see the README's key table)."""

    robot: str = DEFAULT_ROBOT

    def __post_init__(self) -> None:
        _check_chunk(self.robot, "robot id")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.robot}"

    # sim
    @property
    def description(self) -> str:
        return f"{self.prefix}/description"

    @property
    def state(self) -> str:
        return f"{self.prefix}/state"

    @property
    def odom(self) -> str:
        return f"{self.prefix}/odom"

    @property
    def state_truth(self) -> str:
        """The base's true pose and twist (`StateTruth`): evaluation, tests, trials only."""
        return f"{self.prefix}/state_truth"

    @property
    def localization(self) -> str:
        """T_map_odom and its status (`localization.Localization`)."""
        return f"{self.prefix}/localization"

    @property
    def slam_occupancy(self) -> str:
        """The grid the localization builds while mapping (`semantic_map.OccupancyGrid`,
        `static_source` "slam"), published when it changed, at most every
        `localization.slam.publish_every_s`; its stamp goes out on `localization`."""
        return f"{self.prefix}/slam/occupancy"

    @property
    def scan(self) -> str:
        """The trunk lidar's planar scan (`LaserScan`)."""
        return f"{self.prefix}/scan"

    @property
    def scan_rear(self) -> str:
        """The rear lidar's planar scan (`LaserScan`; `sim.sensors.lidar.rear`)."""
        return f"{self.prefix}/scan_rear"

    @property
    def command(self) -> str:
        return f"{self.prefix}/command"

    @property
    def sim_stats(self) -> str:
        """Where the sim's wall time went (`SimStats`), for the stack bench."""
        return f"{self.prefix}/sim/stats"

    def camera_rgbd(self, camera: str) -> str:
        return f"{self.prefix}/camera/{_camera(camera)}/rgbd"

    def camera_segmentation_truth(self, camera: str) -> str:
        return f"{self.prefix}/camera/{_camera(camera)}/segmentation_truth"

    @property
    def camera_rgbd_all(self) -> str:
        return f"{self.prefix}/camera/*/rgbd"

    # perception
    @property
    def detections(self) -> str:
        return f"{self.prefix}/perception/detections"

    @property
    def locate(self) -> str:
        return f"{self.prefix}/perception/locate"

    # navigation
    @property
    def nav_goal(self) -> str:
        return f"{self.prefix}/nav/goal"

    @property
    def nav_cancel(self) -> str:
        return f"{self.prefix}/nav/cancel"

    @property
    def nav_status(self) -> str:
        return f"{self.prefix}/nav/status"

    @property
    def nav_path(self) -> str:
        return f"{self.prefix}/nav/path"

    # whole-body controller
    @property
    def cmd_vel(self) -> str:
        return f"{self.prefix}/wbc/cmd_vel"

    @property
    def arm_goal(self) -> str:
        return f"{self.prefix}/wbc/arm_goal"

    @property
    def wbc_mode(self) -> str:
        return f"{self.prefix}/wbc/mode"

    @property
    def wbc_status(self) -> str:
        return f"{self.prefix}/wbc/status"

    # mission (user-facing, JSON)
    @property
    def mission_request(self) -> str:
        return f"{self.prefix}/mission/request"

    @property
    def mission_submit(self) -> str:
        """A request as a query: answered once the mission holds it (`MissionReceipt`)."""
        return f"{self.prefix}/mission/submit"

    @property
    def mission_cancel(self) -> str:
        return f"{self.prefix}/mission/cancel"

    @property
    def mission_status(self) -> str:
        return f"{self.prefix}/mission/status"

    @property
    def mission_patrol(self) -> str:
        """The mapping patrol's requests (query, JSON): `PatrolRequest` → `PatrolStatus`."""
        return f"{self.prefix}/mission/patrol"

    @property
    def mission_patrol_status(self) -> str:
        """The patrol's `PatrolStatus` at every mission tick (JSON): the map reads whether
        the patrol holds the arm up."""
        return f"{self.prefix}/mission/patrol/status"

    # lockstep and liveliness
    def ack(self, service: str) -> str:
        return f"{self.prefix}/ack/{_check_chunk(service, 'service')}"

    def alive(self, service: str) -> str:
        return f"{ALIVE}/{self.robot}/{_check_chunk(service, 'service')}"

    def alive_run(self, service: str, run: str) -> str:
        """The second token of a service process: which run of it this is (a random id of
        the process; `common.lifelines` tells a lapsed link from a restart by it)."""
        return f"{self.alive(service)}/{_check_chunk(run, 'run')}"

    @property
    def alive_all(self) -> str:
        return f"{ALIVE}/{self.robot}/*"


def _camera(camera: str) -> str:
    if camera not in CAMERAS:
        raise ValueError(f"unknown camera {camera!r}; cameras are {CAMERAS}")
    return camera


def as_of(key: str, at_ns: int | None) -> str:
    """A map query's selector as of a sim time (`?at=<ns>`): the map answers from its state
    after its last tick whose output takes effect by then (a lockstep consumer's view,
    the same in every run); None: its state now."""
    if at_ns is None:
        return key
    return f"{key}{';' if '?' in key else '?'}at={at_ns}"


def service_of_alive_key(key: str) -> str:
    """The service name at the end of a liveliness key `dume/alive/<robot>/<service>`."""
    return key.rsplit("/", 1)[-1]
