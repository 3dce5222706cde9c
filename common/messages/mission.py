"""The user-facing mission API. These travel as JSON so any Zenoh client can use them."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import msgspec

from common.messages.base import Message, StampNs, Unit

RequestId = Annotated[str, msgspec.Meta(min_length=1, max_length=128)]
#: A map id (`bottle_1`) or a class (`bottle`: the nearest mapped one).
Target = Annotated[str, msgspec.Meta(pattern=r"^[a-z][a-z0-9]*(_[1-9][0-9]*)?$", max_length=64)]


class MissionRequest(Message, frozen=True):
    """`dume/<r>/mission/request`: `{"request_id", "object", "person"}`."""

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    request_id: RequestId
    object: Target
    person: Target


class MissionCancel(Message, frozen=True):
    """`dume/<r>/mission/cancel`: `{"request_id", "reason"}`."""

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    request_id: RequestId
    reason: str = ""


MissionState = Literal[
    "idle", "accepted", "running", "succeeded", "failed", "cancelled", "rejected"
]


class MissionStatus(Message, frozen=True):
    """`dume/<r>/mission/status`: the state of a request, echoing its `request_id`.

    behaviour: the running leaf of the tree. progress: [0, 1].
    reason: typed failure code (`unknown_object`, `grasp_failed`, …); detail: a sentence.
    """

    WIRE: ClassVar[Literal["msgpack", "json"]] = "json"
    stamp_ns: StampNs
    request_id: str
    state: MissionState
    behaviour: str = ""
    progress: Unit = 0.0
    reason: str = ""
    detail: str = ""
