"""The user's side of the mission: requests and cancels in, statuses out.

- `parse_request(payload)`: JSON → `MissionRequest`, or a `Rejection` (`malformed`) that
  echoes the payload's `request_id` when one can be read from it (a person must be able
  to tell which of their requests was refused).
- `check_request(request, port)`: the named object and person against the map now
  (`unknown_object`, `unknown_person`; `unavailable` when the map does not answer), so a
  bad request is refused before the robot moves.
- `parse_cancel(payload)`: JSON → `MissionCancel`, or None (logged by the node).
- `StatusBoard`: the mission's current status; `update` says whether it changed (then
  it goes out at once), `due` whether the periodic repeat is due.

Pure apart from the port's map queries.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from common.messages import PayloadError, decode
from common.messages.mission import (
    MissionCancel,
    MissionReason,
    MissionRequest,
    MissionState,
    MissionStatus,
)
from services.mission import targets
from services.mission.ports import RobotPort, Unavailable


@dataclass(frozen=True)
class Rejection:
    """A request refused before it started: its id (as far as it could be read), why."""

    request_id: str
    reason: MissionReason
    detail: str


def _request_id_of(payload: bytes) -> str:
    """The request id of a malformed request, when it has one to echo ("" otherwise: not
    JSON, not an object, or nested past the parser's depth)."""
    try:
        value = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return ""
    rid = value.get("request_id") if isinstance(value, dict) else None
    if not isinstance(rid, str):
        return ""
    return "".join(c for c in rid if c.isprintable())[:128]  # nothing that forges a log line


def parse_request(payload: bytes) -> MissionRequest | Rejection:
    """The request, or why it is malformed (with the error's path into the JSON)."""
    try:
        return decode(payload, MissionRequest)
    except PayloadError as exc:
        return Rejection(_request_id_of(payload), "malformed", str(exc))


def check_request(request: MissionRequest, port: RobotPort) -> Rejection | None:
    """None when the map knows the object and the person; the refusal otherwise."""
    rid = request.request_id
    try:
        if not targets.object_candidates(port, request.object):
            what = "artifact" if targets.is_map_id(request.object) else "artifact of class"
            return Rejection(rid, "unknown_object", f"no mapped {what} {request.object!r}")
        if targets.person_named(port, request.person) is None:
            return Rejection(rid, "unknown_person", f"no mapped person {request.person!r}")
    except Unavailable as exc:
        return Rejection(rid, "unavailable", f"the semantic map did not answer: {exc}")
    return None


def parse_cancel(payload: bytes) -> MissionCancel | None:
    try:
        return decode(payload, MissionCancel)
    except PayloadError:
        return None


class StatusBoard:
    """The current mission status and when to publish it (see the module docstring)."""

    def __init__(self, every_ns: int) -> None:
        self.every_ns = every_ns
        self.status = MissionStatus(stamp_ns=0, request_id="", state="idle")
        self.sent_ns = -(10**18)

    def update(
        self,
        stamp_ns: int,
        request_id: str,
        state: MissionState,
        behaviour: str = "",
        progress: float = 0.0,
        reason: MissionReason = "",
        detail: str = "",
    ) -> bool:
        """Set the status; True when anything but the stamp changed (publish it now)."""
        new = MissionStatus(
            stamp_ns=stamp_ns,
            request_id=request_id,
            state=state,
            behaviour=behaviour,
            progress=round(min(1.0, max(0.0, progress)), 2),
            reason=reason,
            detail=detail,
        )
        old = self.status
        self.status = new
        return (old.request_id, old.state, old.behaviour, old.progress, old.reason) != (
            new.request_id,
            new.state,
            new.behaviour,
            new.progress,
            new.reason,
        )

    def due(self, stamp_ns: int) -> bool:
        return stamp_ns - self.sent_ns >= self.every_ns

    def sent(self, stamp_ns: int) -> MissionStatus:
        """The status stamped now, marked as sent."""
        self.sent_ns = stamp_ns
        self.status = MissionStatus(
            stamp_ns=stamp_ns,
            request_id=self.status.request_id,
            state=self.status.state,
            behaviour=self.status.behaviour,
            progress=self.status.progress,
            reason=self.status.reason,
            detail=self.status.detail,
        )
        return self.status
