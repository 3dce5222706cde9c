"""The arm goals' intake: accept or refuse a request, hold it until its effective tick.

Threads: `accept` runs on the `wbc/arm_goal` query server's thread, `due` on the WBC's;
`_lock` guards the pending queue and the goal counter. The mode is read without the lock
through `mode` (one attribute read), as the request is checked.

Refusals (`common.bus.RequestError`, answered as a typed `ErrorReply`): no request
(malformed), any goal in mode damp (unavailable), a Reach outside mode manipulate (busy),
a Reach whose H is not a rigid transform (invalid, `arm_actions.check_reach`). An
accepted goal gets the id `arm_<n>` (n counts from 1) and waits for the first tick at or
after its `effective_ns` (ns of sim time; none: the next tick); goals due at one tick
start in the order they were accepted (`arm_actions.ArmActions.start`, by the caller).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

from common.bus import RequestError
from common.messages.wbc import ArmGoal, ArmGoalReply, ArmGoalRequest, Reach, WbcModeName
from services.wbc.arm_actions import GoalRefused, check_reach

#: An accepted goal: (id, goal, effective stamp ns or -1 for at once).
Pending = tuple[str, ArmGoal, int]


class GoalIntake:
    """Accepted arm goals waiting for their tick, in arrival order."""

    def __init__(self, mode: Callable[[], WbcModeName], log: logging.Logger) -> None:
        self.mode, self.log = mode, log
        self._lock = threading.Lock()
        self._pending: deque[Pending] = deque()
        self._count = 0

    def accept(self, req: ArmGoalRequest | None) -> ArmGoalReply:
        """Queue the request's goal (the server's thread); RequestError to refuse it."""
        if req is None:
            raise RequestError("malformed", "an ArmGoalRequest is needed")
        goal, mode = req.goal, self.mode()
        if mode == "damp":
            raise RequestError("unavailable", "mode damp: the arm takes no goals")
        if isinstance(goal, Reach):
            if mode != "manipulate":
                raise RequestError("busy", f"mode {mode}: a reach needs mode manipulate")
            try:
                check_reach(goal)
            except GoalRefused as exc:
                raise RequestError("invalid", str(exc)) from None
        with self._lock:
            self._count += 1
            goal_id = f"arm_{self._count}"
            effective = -1 if req.effective_ns is None else req.effective_ns
            self._pending.append((goal_id, goal, effective))
        self.log.info("arm goal %s accepted: %s", goal_id, type(goal).__name__)
        return ArmGoalReply(accepted=True, goal_id=goal_id)

    def due(self, t: int) -> list[Pending]:
        """Take the goals effective at or before t (ns), in the order they were accepted
        (the WBC's thread); the others stay queued."""
        with self._lock:
            due = [p for p in self._pending if p[2] <= t]
            self._pending = deque(p for p in self._pending if p[2] > t)
        return due
