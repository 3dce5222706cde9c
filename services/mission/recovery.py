"""`Recover`: a retry decorator that decides on the failure's typed reason.

py_trees' `Retry` retries on any failure; the mission must retry only what a retry can
mend (a grasp lost: pick again; an object not where the map says: the next instance),
within a budget, and report anything else at once. On the child's FAILURE, `Recover`
reads the blackboard's `failure`: when its reason is one of `reasons`, the budget is not
spent and `prepare(failure)` agrees (it also sets the blackboard up for the next try,
e.g. moves to the next candidate), it returns RUNNING and the child starts over on the
next tick; otherwise it fails with the child's reason. The budget resets when the
decorator itself starts again.
"""

from __future__ import annotations

from collections.abc import Callable

import py_trees
from py_trees.common import Status

from services.mission.behaviours.base import FAILURE, Decide, Failure, blackboard, read

Prepare = Callable[[Failure], bool]


class Recover(py_trees.decorators.Decorator):
    def __init__(
        self,
        name: str,
        child: py_trees.behaviour.Behaviour,
        reasons: frozenset[str],
        budget: int,
        decide: Decide,
        prepare: Prepare | None = None,
    ) -> None:
        super().__init__(name=name, child=child)
        self.reasons, self.budget, self.decide = reasons, budget, decide
        self.prepare = prepare
        self.used = 0
        self.bb = blackboard(name, (FAILURE,))

    def initialise(self) -> None:
        self.used = 0

    def update(self) -> Status:
        status = self.decorated.status
        if status != Status.FAILURE:
            return status
        failure = read(self.bb, FAILURE)
        if not isinstance(failure, Failure) or failure.reason not in self.reasons:
            return Status.FAILURE
        if self.used >= self.budget:
            self.decide(f"{self.name}: {failure.reason} again, budget of {self.budget} spent")
            self.feedback_message = f"budget of {self.budget} spent"
            return Status.FAILURE
        if self.prepare is not None and not self.prepare(failure):
            self.decide(f"{self.name}: {failure.reason}, nothing left to try")
            return Status.FAILURE
        self.used += 1
        self.decide(f"{self.name}: {failure.reason}: try {self.used} of {self.budget}")
        self.feedback_message = f"try {self.used} of {self.budget} after {failure.reason}"
        self.bb.set(FAILURE, None)
        return Status.RUNNING
