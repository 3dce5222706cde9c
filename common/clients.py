"""Goal clients: the one way to send navigation and arm goals and to cancel them.

Every caller (the mission's robot port, for its fetch and its patrol; trials and benches)
goes through `NavClient` and `ArmClient`, so a goal is sent, refused and reported the same
way everywhere:

- `send` asks the goal queryable once and returns the goal's id. The server's typed
  refusal (an `ErrorReply`, or a reply with `accepted=False`) raises `Refused` with its
  code and reason; no answer within `timeout_s`, or an answer that is not a reply, raises
  `Unavailable`. There is no retry: navigation takes a goal sent before its map is in
  (it queues it), and the whole-body controller answers from its first tick, so a
  refusal is an answer and a silence is a fault, never a reason to ask again.
- Times: `stamp_ns` is the sender's sim tick (navigation resolves the goal against its
  state as of that tick); `effective_ns` is when the goal takes effect (the sender's
  tick plus its lockstep latency). Both None outside lockstep: the newest state, at
  once.
- The goal's progress is read from the server's status stream (`nav/status`,
  `wbc/status`) by the caller, as of its own tick; a client holds no state.
"""

from __future__ import annotations

from common.bus import Bus, BusError, NoReply, RemoteError
from common.keys import RobotKeys
from common.messages import PayloadError
from common.messages.navigation import NavCancel, NavGoal, NavGoalReply, NavGoalRequest
from common.messages.wbc import ArmGoal, ArmGoalReply, ArmGoalRequest


class ClientError(Exception):
    """A request the robot's services did not serve: the reason, for a person, and the
    service's typed code when it gave one (`ErrorCode`: `unavailable`, `busy`, …)."""

    def __init__(self, message: str, code: str = "") -> None:
        super().__init__(message)
        self.code = code


class Refused(ClientError):
    """The service answered and said no (its typed reason in the message)."""


class Unavailable(ClientError):
    """Nobody answered within the timeout (the service is down or stalled)."""

    def __init__(self, message: str, code: str = "unavailable") -> None:
        super().__init__(message, code)


def _send(
    bus: Bus,
    key: str,
    request: NavGoalRequest | ArmGoalRequest,
    reply_type: type[NavGoalReply] | type[ArmGoalReply],
    timeout_s: float,
) -> str:
    try:
        reply = bus.query(key, request, reply_type, timeout_s)
    except RemoteError as exc:
        raise Refused(f"{exc.error.code}: {exc.error.message}", exc.error.code) from None
    except (NoReply, PayloadError, BusError) as exc:
        raise Unavailable(str(exc)) from None
    if not reply.accepted:
        raise Refused(reply.reason)
    return reply.goal_id


class NavClient:
    """Navigation goals (`nav/goal`) and cancels (`nav/cancel`)."""

    def __init__(self, bus: Bus, keys: RobotKeys, timeout_s: float) -> None:
        self.bus, self.key, self.timeout_s = bus, keys.nav_goal, timeout_s
        self._cancel = bus.publisher(keys.nav_cancel, NavCancel, "data")

    def send(
        self, goal: NavGoal, *, stamp_ns: int | None = None, effective_ns: int | None = None
    ) -> str:
        """The goal's id; `Refused` or `Unavailable`."""
        request = NavGoalRequest(goal=goal, stamp_ns=stamp_ns, effective_ns=effective_ns)
        return _send(self.bus, self.key, request, NavGoalReply, self.timeout_s)

    def cancel(self, goal_id: str, reason: str, *, effective_ns: int | None = None) -> None:
        """Cancel `goal_id` ("" cancels whichever is active or waiting)."""
        self._cancel.put(NavCancel(goal_id=goal_id, reason=reason, effective_ns=effective_ns))


class ArmClient:
    """Arm goals (`wbc/arm_goal`): postures, reaches, grips."""

    def __init__(self, bus: Bus, keys: RobotKeys, timeout_s: float) -> None:
        self.bus, self.key, self.timeout_s = bus, keys.arm_goal, timeout_s

    def send(self, goal: ArmGoal, *, effective_ns: int | None = None) -> str:
        """The goal's id; `Refused` or `Unavailable`."""
        request = ArmGoalRequest(goal=goal, effective_ns=effective_ns)
        return _send(self.bus, self.key, request, ArmGoalReply, self.timeout_s)
