"""What every mission behaviour shares: the context, the blackboard, failing with a reason.

A behaviour is a py_trees `Behaviour` that talks to the robot only through the
`RobotPort` in its `Context`, keeps the mission's data on the blackboard under
`/mission` (keys registered with their access), and ends a failure with `fail(reason,
detail)`: the typed reason and the sentence go to the blackboard's `failure`, where the
recovery decorators decide and `abort` reports. Time is the port's sim time.

`stage`: which of the paper's six stages a leaf belongs to (for `mission/status`);
`fraction`: how far the leaf is, [0, 1], where it can tell (navigation's progress).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import py_trees
from py_trees.common import Access, Status

from common.config import MissionSettings
from common.messages.base import NS_PER_S
from common.messages.mission import MissionReason, Taken
from services.mission.algorithms import Algorithms
from services.mission.ports import RobotPort

NAMESPACE = "/mission"


#: Blackboard keys, all under /mission.
REQUEST = "request"  # MissionRequest
CANDIDATES = "candidates"  # list[str]: map ids of the object, nearest first
CANDIDATE = "candidate"  # int: index of the candidate being fetched
TARGET = "target"  # Target: the object being fetched
PERSON = "person"  # str: the person's map id
FACING = "facing"  # bool: the map knows which way the person faces
SIDE = "side"  # tuple[float, int] | None: the bearing round the person first tried, try k
DETECTION = "detection"  # tuple[int, Detection] | None: the grasp's detection
GRASP_PLAN = "grasp_plan"  # a GraspPlan
FAILURE = "failure"  # Failure | None
SEARCH = "search"  # bool: look elsewhere before the next try (every candidate missed)
SEARCHED = "searched"  # bool: this request looked elsewhere already
SEARCH_LEFT = "search_left"  # SearchLeft | None: a search that stopped at a find, the rest
UNSEEN = "unseen"  # bool: the person was not seen at their mapped place: look round
KNOWN = "known"  # list[str]: the map's artifacts of the class when the request began
LOOK_AT = "look_at"  # SeenPlace | None: the person's usual place walked to next, to look
LOOKED = "looked"  # list[tuple[float, float]]: where the robot looked round for the person
STANCE = "stance"  # float | None: the world yaw of the line of sight the grasp needs (±)
PERSON_LOOK = "person_look"  # identity.Look | None: the requested person's colours, noted
OTHERS = "others"  # list[str]: map people found at the handover in other clothes
STOW_BACK = "stow_back"  # float: m the base backs off before the stow (`stow_room`)
ALL_KEYS = (
    REQUEST, CANDIDATES, CANDIDATE, TARGET, PERSON, FACING, SIDE, DETECTION, GRASP_PLAN, FAILURE,
    SEARCH, SEARCHED, SEARCH_LEFT, UNSEEN, KNOWN, LOOK_AT, LOOKED, STANCE, PERSON_LOOK, OTHERS,
    STOW_BACK,
)  # fmt: skip


@dataclass(frozen=True)
class Target:
    """The object being fetched: its map id, class and mapped place (world x, y; None
    when the map did not say). `dropped`: it fell from the gripper while carried, and
    `xy` is where, as the gripper's place at the loss says (None: the robot's own place
    was unknown); it is looked for there, the nearest of its class, not at the map's."""

    map_id: str
    class_name: str
    xy: tuple[float, float] | None = None
    dropped: bool = False

    @property
    def look_near(self) -> tuple[float, float] | None:
        """Where the wrist camera's detection of it is picked (`RobotPort.wrist_detection`):
        its mapped place, or where it fell once dropped (None, where unknown: the nearest
        of its class). The approach takes any artifact class there: the network never saw
        an object lying on a floor, and reads a knocked-down bottle as a box."""
        return self.xy

    def where_dropped(self) -> str:
        """Where it fell, for a person."""
        return "near the robot" if self.xy is None else f"at ({self.xy[0]:.2f}, {self.xy[1]:.2f})"


@dataclass(frozen=True)
class Held:
    """An object the gripper still holds from a request that ended unfinished: its map
    id, the request's id, the grasp's plan (world frame: the map's) and where the base
    stood for it (map x, y, yaw; None: unknown, and it cannot be put back)."""

    map_id: str
    request_id: str
    plan: Any = None
    stance: tuple[float, float, float] | None = None

    @property
    def can_put_back(self) -> bool:
        """Whether the robot knows where it picked it: a world plan and a stance."""
        return self.stance is not None and getattr(self.plan, "frame", "") == "world"


@dataclass(frozen=True)
class Failure:
    """Why a leaf failed: the typed reason, a sentence, which leaf, when (sim ns)."""

    reason: MissionReason
    detail: str
    behaviour: str
    stamp_ns: int


Decide = Callable[[str], None]


@dataclass
class Context:
    """What every behaviour gets: the robot, the settings, the algorithms and a way to
    say a decision (logged with sim time and to rerun by the node)."""

    port: RobotPort
    settings: MissionSettings
    algorithms: Algorithms
    decide: Decide = field(default=lambda text: logging.getLogger("dume.mission").info(text))
    #: The objects this mission service handed over (map id → to whom, when, sim ns): a
    #: request by class does not fetch one again, and one by id is told where it went
    #: (the map keeps its entry where it last saw it: in a hand, or on its old support),
    #: until the map sees it put down again (`targets.put_back`: it leaves this then).
    handed: dict[str, tuple[str, int]] = field(default_factory=dict)
    #: What the robot still holds from a request that ended unfinished (`Held`): the next
    #: request that asks for it brings it without a fetch; one that asks for something
    #: else puts it back where it was picked first.
    holding: Held | None = None
    #: Where the base stood (map x, y, yaw) when the grasp detector last said held.
    picked_from: tuple[float, float, float] | None = None
    #: The robot's latest takes, oldest first (`Taken`, at most `TAKEN_KEPT`): the map
    #: reads them on the patrol status and marks what was taken missing at its place.
    taken: list[Taken] = field(default_factory=list)
    #: What this request put back (a sentence; "" when nothing): a `put_back`'s outcome.
    put_back: str = ""


def blackboard(name: str, writes: Sequence[str] = ()) -> py_trees.blackboard.Client:
    """A client that reads every mission key and writes only `writes` (py_trees refuses
    a write to any other: who changes what is declared, and checked)."""
    client = py_trees.blackboard.Client(name=name, namespace=NAMESPACE)
    for key in ALL_KEYS:
        client.register_key(key=key, access=Access.WRITE if key in writes else Access.READ)
    return client


def reset_blackboard() -> None:
    """A clean mission: every key unset (the blackboard is process-global)."""
    for key in ALL_KEYS:
        py_trees.blackboard.Blackboard.unset(f"{NAMESPACE}/{key}")


def read(client: py_trees.blackboard.Client, key: str, default: Any = None) -> Any:
    """A key's value, or `default` when it is not set."""
    return client.get(key) if client.exists(key) else default


class MissionBehaviour(py_trees.behaviour.Behaviour):
    """Base of the mission's leaves (see the module docstring). Every leaf may write
    `FAILURE` (`fail`); the keys it writes besides are its `WRITES`."""

    WRITES: ClassVar[tuple[str, ...]] = ()

    def __init__(self, name: str, ctx: Context, stage: str) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.port = ctx.port
        self.settings = ctx.settings
        self.stage = stage
        self.fraction = 0.0
        self.bb = blackboard(name, (FAILURE, *self.WRITES))
        self.started_ns = 0
        #: What the status says while this leaf runs, when not its name (a sentence).
        self.say = ""

    def initialise(self) -> None:
        self.started_ns = self.port.now_ns
        self.fraction = 0.0
        self.feedback_message = ""
        self.say = ""

    def elapsed_s(self) -> float:
        """Sim seconds since this activation began."""
        return (self.port.now_ns - self.started_ns) / NS_PER_S

    def get(self, key: str, default: Any = None) -> Any:
        return read(self.bb, key, default)

    def set(self, key: str, value: Any) -> None:
        self.bb.set(key, value)

    def target(self) -> Target:
        target = self.get(TARGET)
        if not isinstance(target, Target):
            raise RuntimeError(f"{self.name}: no target on the blackboard (tree misbuilt)")
        return target

    def forget_failure(self, reason: MissionReason) -> Failure | None:
        """The blackboard's failure, forgotten, when it is of `reason` (a recovery leaf
        that takes it over); None, and it stays, otherwise."""
        failure = self.get(FAILURE)
        if not isinstance(failure, Failure) or failure.reason != reason:
            return None
        self.set(FAILURE, None)
        return failure

    def fail(self, reason: MissionReason, detail: str) -> Status:
        """Record why, say it, and return FAILURE."""
        self.feedback_message = f"{reason}: {detail}"
        self.set(FAILURE, Failure(reason, detail, self.name, self.port.now_ns))
        self.ctx.decide(f"{self.name} failed: {reason}: {detail}")
        return Status.FAILURE
