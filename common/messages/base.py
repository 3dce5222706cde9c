"""Shared building blocks of every message.

Every payload is a frozen msgspec Struct that rejects unknown fields. Floats that must be
finite use `Finite` (NaN and ±inf fail validation with the field's path). Time is sim
time in integer nanoseconds (`stamp_ns`): the sim ticks at 1 kHz, so stamps are exact.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal

import msgspec

#: A finite float: NaN and infinities fail validation.
Finite = Annotated[float, msgspec.Meta(ge=-1e12, le=1e12)]
#: A finite, non-negative float.
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=1e12)]
#: A probability or fraction in [0, 1].
Unit = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
#: Sim time in nanoseconds.
StampNs = Annotated[int, msgspec.Meta(ge=0)]
#: An id like `bottle_1` or `person_2`.
EntityId = Annotated[str, msgspec.Meta(pattern=r"^[a-z][a-z0-9]*_[1-9][0-9]*$", max_length=64)]
#: A class name like `bottle` or `person`.
ClassName = Annotated[str, msgspec.Meta(pattern=r"^[a-z][a-z0-9]*$", max_length=32)]

Vec3 = tuple[Finite, Finite, Finite]
#: A unit quaternion, x y z w (MuJoCo's w x y z is converted at the sim boundary).
QuatXYZW = tuple[Finite, Finite, Finite, Finite]
#: A 4×4 homogeneous transform, row-major.
Mat4 = Annotated[tuple[Finite, ...], msgspec.Meta(min_length=16, max_length=16)]

#: How far a `QuatXYZW`'s norm may be from 1: senders normalise (MuJoCo, pinocchio), a
#: float32 round trip stays far inside, a zero or garbage quaternion is far outside.
QUAT_NORM_TOL = 1e-2


def check_unit_quaternion(q: tuple[float, ...], field: str) -> None:
    """Raise ValueError (a validation error when decoding) unless `q` is a unit quaternion:
    a zero one has no rotation, and every reader would fail on it later, far from here."""
    norm = math.sqrt(sum(c * c for c in q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise ValueError(f"{field} is not a unit quaternion (norm {norm:.3g})")


#: Nanoseconds per second (sim time is integer ns): the one definition, import it from here.
NS_PER_S = 1_000_000_000


class Message(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Base of every payload. `WIRE` says how it travels: msgpack, or JSON for users.
    `WALL_CLOCK` names the fields that are wall-clock figures (for monitoring): they
    differ between two runs of one seed by design, so a run's trace leaves them out.
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "msgpack"
    WALL_CLOCK: ClassVar[tuple[str, ...]] = ()


class Pose(Message, frozen=True):
    """A rigid pose.

    position: (3,) m, in the frame named by the field that holds the pose.
    orientation_xyzw: (4,) unit quaternion, x y z w.
    """

    position: Vec3
    orientation_xyzw: QuatXYZW = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        check_unit_quaternion(self.orientation_xyzw, "orientation_xyzw")


class Pose2D(Message, frozen=True):
    """A planar pose in the world frame: x, y in m, yaw in rad about z (counter-clockwise)."""

    x: Finite
    y: Finite
    yaw: Finite = 0.0


def seconds(stamp_ns: int) -> float:
    """Sim time in seconds from nanoseconds."""
    return stamp_ns / NS_PER_S


def to_ns(seconds_: float) -> int:
    """Sim time in nanoseconds from seconds, rounded to the nanosecond."""
    return round(seconds_ * NS_PER_S)
