"""The user-facing mission API: requests (a fetch, an exploration, a mapping patrol),
cancels, statuses, and the mapping jobs' own status. These travel as JSON so any Zenoh
client can use them."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import msgspec

from common.messages.base import ClassName, EntityId, Finite, Message, NonNegative, StampNs, Unit

#: Any text without control characters (a NUL, a newline or an escape in an id went into
#: the logs as they were: `dume trial fuzz`).
RequestId = Annotated[
    str, msgspec.Meta(min_length=1, max_length=128, pattern=r"^[^\x00-\x1f\x7f-\x9f]+$")
]
#: A map id (`bottle_1`) or a class (`bottle`: the nearest mapped one); "" for none.
Target = Annotated[str, msgspec.Meta(pattern=r"^([a-z][a-z0-9]*(_[1-9][0-9]*)?)?$", max_length=64)]
#: What a request asks the robot to do: bring an object to a person (`fetch`), put what
#: the gripper still holds from an unfinished fetch back where it was picked
#: (`put_back`), map the place from nothing by frontier exploration (`explore`), or walk
#: the mapping patrol's coverage route over the map it has (`patrol`).
Task = Literal["fetch", "put_back", "explore", "patrol"]
#: The mapping jobs (`Task` less the fetch and the put-back, which the bring-me tree runs).
JobTask = Literal["patrol", "explore"]


class MissionRequest(Message, frozen=True, omit_defaults=True):
    """`dume/<r>/mission/request`: `{"request_id", "object", "person"}` (a fetch), or
    `{"request_id", "task": "put_back"}` / `"explore"` / `"patrol"`.

    task: `fetch` (the default: a request without it is a fetch) needs `object` and
    `person`; `put_back`, `explore` and `patrol` take neither. A request that breaks this does not
    decode (the mission rejects it `malformed`, saying which field).
    at_ns: sim time before which the mission does not take it (held until its tick
    reaches it; a user leaves it out): an evaluation's shift sends each request ahead of
    its time, so a lockstep run of many requests is as repeatable as one of one.
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    request_id: RequestId
    object: Target = ""
    person: Target = ""
    task: Task = "fetch"
    at_ns: StampNs | None = None

    def __post_init__(self) -> None:
        if self.task == "fetch":
            missing = [name for name in ("object", "person") if not getattr(self, name)]
            if missing:
                raise ValueError(f"a fetch needs {' and '.join(missing)}: none given")
        elif self.object or self.person:
            raise ValueError(f"task {self.task} takes no object or person")


class MissionReceipt(Message, frozen=True):
    """The answer of `dume/<r>/mission/submit`: the mission holds the request, which it
    takes at its next tick (its status follows on `mission/status` as for a put)."""

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    request_id: RequestId


class MissionCancel(Message, frozen=True):
    """`dume/<r>/mission/cancel`: `{"request_id", "reason"}`."""

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    request_id: RequestId
    reason: str = ""


MissionState = Literal[
    "idle", "accepted", "running", "succeeded", "failed", "cancelled", "rejected"
]

#: Every typed reason a mission status may carry (the one list; `detail` has the sentence).
MissionReason = Literal[
    "",
    # a request refused before it starts (state `rejected`)
    "malformed",  # not JSON, not an object, a field missing or of the wrong type
    "busy",  # another mission, an exploration or the mapping patrol runs: one job at a time
    "unknown_object",  # no mapped artifact has that id, or none of that class
    "unknown_person",  # no mapped person has that id
    "unavailable",  # a service the mission needs did not answer (the map, navigation, wbc)
    # a mission that ran and stopped (state `failed` or `cancelled`)
    "navigation_failed",  # navigation refused the goal or did not reach it
    "object_not_found",  # approach or pose estimation could not see the object
    "blocked_by_person",  # a person stayed in the base's way longer than it waits for them
    "grasp_pose_failed",  # no grasp possible from what was seen, or its reach stopped far short
    "arm_failed",  # an arm goal (posture, reach, release) failed or timed out
    "grasp_failed",  # the reach to the grasp, the jaw or the lift failed (re-picked first)
    "grasp_lost",  # the object was lost while carrying it, and the re-pick budget is spent
    "object_dropped",  # it fell while carried where the robot cannot pick it up again (on
    # the floor, out of the arm's reach) or was not seen where it fell: said where
    "handover_timeout",  # nobody took the object in time
    "person_not_found",  # the person was not reached: not seen where the robot looked for
    # them, or walking on: said where it looked and where the map last saw them
    "wrong_person",  # the person at the handover wears other clothes than the one asked for,
    # and nobody in the map wears theirs: not handed over (said with the colour distances)
    "mode_timeout",  # the whole-body controller did not take the mode asked for
    "dependency_lost",  # a service it depends on went away or restarted while it ran
    "no_route",  # explore, patrol: no free floor the robot can reach in the map's grid
    "budget",  # explore: its budget of goals or sim time ran out with frontiers left
    "cancelled",  # the user cancelled (state `cancelled`)
    "internal",  # a bug: logged with its traceback; the service kept running
]


#: The paper's stages of the tree, in order: a running status's `behaviour` names one at
#: the start of each (the mission's progress and the eval's per-stage table count them).
STAGES = (
    "navigate_to_object",
    "approach_object",
    "pose_estimation",
    "pick_object",
    "bring_to_user",
    "release_object",
)


class MissionStatus(Message, frozen=True):
    """`dume/<r>/mission/status`: the state of a request, echoing its `request_id`.

    behaviour: the running leaf of the tree. progress: [0, 1].
    reason: typed failure code (`MissionReason`); detail: a sentence for a person.
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    stamp_ns: StampNs
    request_id: str
    state: MissionState
    behaviour: str = ""
    progress: Unit = 0.0
    reason: MissionReason = ""
    detail: str = ""


PatrolState = Literal["idle", "running", "done", "failed", "stopped", "rejected"]

#: Every typed reason a patrol status may carry (`detail` has the sentence).
PatrolReason = Literal[
    "",
    # a start refused (state `rejected`)
    "busy",  # a fetch or another patrol is running: one job at a time
    "unavailable",  # no odometry, the map's grid did not come, or a service is not running
    "no_route",  # the map's grid has no free space reachable from the robot
    # a patrol that ran and failed (state `failed`)
    "navigation_failed",  # navigation refused the patrol's goals altogether
    "dependency_lost",  # a service it depends on went away or restarted while it ran
    "budget",  # explore: its budget of goals or sim time ran out with frontiers left
    "internal",  # a bug: logged with its traceback; the service kept running
]


class PatrolRequest(Message, frozen=True):
    """`dume/<r>/mission/patrol` (query): start or stop the mapping patrol, or ask its
    state: `{"action": "start"}`.

    spacing_m: distance between the route's viewpoints (start only; 0: the configured
    `mission.patrol_spacing_m`).
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    action: Literal["start", "stop", "status"]
    spacing_m: NonNegative = 0.0


#: How many of the robot's latest takes a `PatrolStatus` carries.
TAKEN_KEPT = 8


class Taken(Message, frozen=True):
    """An object the robot took from its place: the map id the mission picked it as,
    its class, where the gripper closed on it (world x, y, m), when (sim ns). The map
    marks the entry there missing (`semantic_map.mapper.SemanticMap.taken`): what the
    robot carries away is not on its support any more."""

    stamp_ns: StampNs
    map_id: EntityId
    class_name: ClassName
    xy: tuple[Finite, Finite]


class PatrolStatus(Message, frozen=True):
    """The mapping job's state (the patrol's, or an exploration's): the reply to
    `dume/<r>/mission/patrol`, and published on `dume/<r>/mission/patrol/status` at every
    mission tick.

    task: which job (`patrol`, `explore`). waypoint, waypoints: the viewpoint being
    walked to or looked around at, of how many (an exploration: the goals looked around
    at, of those chosen so far). travelled_m: path length walked so far. known_m2: the
    known-free floor in the map when the exploration last looked, m² (0 for a patrol).
    arm_look: the job holds the arm in `look`
    now (the wrist camera sees bench tops: the map fuses `semantic_map.patrol_cameras`
    too). taken: the robot's latest takes (`Taken`, at most `TAKEN_KEPT`, a fetch's as
    well as a job's), for the map; every status carries them, as the map reads one
    status a tick and may skip some. reason: typed (`PatrolReason`), for a start
    refused (`rejected`, only in that reply) or a patrol failed; detail: a sentence for a
    person (skipped viewpoints, why it stopped).
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    stamp_ns: StampNs
    state: PatrolState
    task: JobTask = "patrol"
    waypoint: int = 0
    waypoints: int = 0
    travelled_m: NonNegative = 0.0
    known_m2: NonNegative = 0.0
    arm_look: bool = False
    taken: Annotated[tuple[Taken, ...], msgspec.Meta(max_length=TAKEN_KEPT)] = ()
    reason: PatrolReason = ""
    detail: str = ""
