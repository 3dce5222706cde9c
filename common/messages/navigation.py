"""Navigation's goal / cancel / status API and its path."""

from __future__ import annotations

import math
from typing import Annotated, Literal

import msgspec

from common.messages.arrays import Array
from common.messages.base import EntityId, Finite, Message, NonNegative, StampNs, Unit

#: A speed cap, m/s: at least 0, inf for none (NaN fails).
Cap = Annotated[float, msgspec.Meta(ge=0.0)]


class PoseGoal(Message, frozen=True, tag="pose"):
    """Walk to (x, y, yaw) in the world; tolerances in m and rad."""

    x: Finite
    y: Finite
    yaw: Finite
    position_tolerance_m: NonNegative = 0.1
    yaw_tolerance_rad: NonNegative = 0.1


class ArtifactStandoff(Message, frozen=True, tag="artifact_standoff"):
    """Walk to an obstacle-free pose in front of a mapped artifact, facing it.

    bearings_rad: the sides to stand on, as world bearings from the artifact to the
    robot, each within `bearing_tolerance_rad` (the one nearest a bearing that is free);
    empty: in front of it, off the nearest edge of its support (a box whose grasp needs
    the line of sight along its long faces sends both ends of that line)."""

    artifact_id: EntityId
    bearings_rad: Annotated[tuple[Finite, ...], msgspec.Meta(max_length=8)] = ()
    bearing_tolerance_rad: Annotated[float, msgspec.Meta(ge=0.0, le=math.pi)] = math.pi


class PersonHandover(Message, frozen=True, tag="person_handover"):
    """Walk to a pose facing a mapped person at handover distance.

    bearing_rad: the side to stand on, as the world bearing from the person to the
    robot (rad); None: in front of them when the map knows which way they face, else on
    the robot's side (the mission's search round a person whose facing is unknown sends
    the sides it tries). extra_m: how much farther than `common.robot.HANDOVER_DISTANCE_M`
    to stand (an object held out that reaches farther past the gripper than a bottle:
    a box held by its near end would press into the person's arm)."""

    person_id: EntityId
    bearing_rad: Finite | None = None
    extra_m: Annotated[float, msgspec.Meta(ge=0.0, le=0.5)] = 0.0


NavGoal = PoseGoal | ArtifactStandoff | PersonHandover


class NavGoalRequest(Message, frozen=True):
    """`dume/<r>/nav/goal` (query): a goal; replaced goals are cancelled.

    stamp_ns: the sender's tick (a lockstep participant's): navigation plans the goal from
    its own state as of then (its tick one latency earlier, which it has surely done), and
    the map's. effective_ns: the sender's tick plus its lockstep latency; the goal starts
    at navigation's first tick at or after it (the sim cannot get there before the
    sender's ack, which follows the reply). None for both: now and at the next tick (a
    person's or a trial's goal), as the run's timing falls.
    """

    goal: NavGoal
    stamp_ns: StampNs | None = None
    effective_ns: StampNs | None = None


class NavGoalReply(Message, frozen=True):
    """Accepted with a goal id, or refused with a reason."""

    accepted: bool
    goal_id: str = ""
    reason: str = ""


class NavCancel(Message, frozen=True):
    """`dume/<r>/nav/cancel`: cancel a goal (empty id: whatever is active).

    effective_ns: as `NavGoalRequest`'s: at navigation's first tick at or after it (None:
    its next tick).
    """

    goal_id: str = ""
    reason: str = ""
    effective_ns: StampNs | None = None


NavState = Literal["idle", "active", "succeeded", "failed", "cancelled"]
NavFailure = Literal["", "no_path", "blocked", "timeout", "invalid_goal", "cancelled"]


class ScanBody(Message, frozen=True):
    """A body the lidars track near the robot (the speed monitor's protective field,
    `services.navigation.scan_people`): a person to the speed rules, of unknown identity.
    id: the track's (`scan_<k>`, a new one when the track breaks up); x, y: its floor
    point (m, world); velocity (m/s, world): None until measured."""

    id: str
    x: Finite
    y: Finite
    velocity: tuple[Finite, Finite] | None = None


class NavStatus(Message, frozen=True):
    """`dume/<r>/nav/status`: the current goal's state.

    progress: [0, 1] of the path length. remaining_m: along the path, m.
    reason: the typed failure (`NavFailure`); detail: a sentence for a person.
    """

    stamp_ns: StampNs
    goal_id: str
    state: NavState
    reason: NavFailure = ""
    detail: str = ""
    progress: Unit = 0.0
    remaining_m: NonNegative = 0.0
    #: The speed and separation monitor's caps (m/s; inf: none) on a translation along
    #: the base's axes, ahead, behind, left, right, for what drives the base without a
    #: goal (the mission's cmd_vel); `cap_person`: who sets the tightest. 0 while
    #: navigation does not know where the robot is (localization lost).
    caps_mps: tuple[Cap, Cap, Cap, Cap] = (
        math.inf, math.inf, math.inf, math.inf,
    )  # fmt: skip
    cap_person: str = ""
    #: How far from the base origin (m; inf: none within `body_guard.ROOM_REACH_M` of
    #: the footprint) the static world navigation knows (the map's obstacles and the
    #: depth layer's) lies ahead, behind, left, right, in the band the body sweeps along
    #: that axis (`body_guard.clearance`), for the same drivers: less the body's extent
    #: that way, the room they have. Negative: an obstacle under the body.
    clear_m: tuple[float, float, float, float] = (
        math.inf, math.inf, math.inf, math.inf,
    )  # fmt: skip
    #: The lidars' bodies within `scan_people.TRACKS_SAID_M` of the base, nearest first
    #: (who walks by where the head camera does not look: the mission looks at them while
    #: it looks for a person).
    bodies: Annotated[tuple[ScanBody, ...], msgspec.Meta(max_length=16)] = ()


class NavPath(Message, frozen=True):
    """`dume/<r>/nav/path`: the plan, (N, 3) float64 x, y, yaw in the world frame."""

    stamp_ns: StampNs
    goal_id: str
    poses: Array
