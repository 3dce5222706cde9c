"""`WhileHeld`: a carry that fails `grasp_lost` the tick the gripper lets go, whatever
leaf of it runs.

The walks that carried the object watched the grasp themselves (`NavigateTo`'s
`watch_held`, now gone), but the rest of the carry did not: in a shift, a can fell while the robot
turned to look for the person (hall seed 3, t = 224.7 s), and the mission learned it
28 s later, when its next walk began, having turned, asked and set off to a usual place
of the person's with an empty gripper meanwhile. `WhileHeld` reads the WBC's grasp
detector (`WbcStatus.held`) before each tick of its child: held, or no status yet, the
child ticks; let go, the running leaf is stopped (a walk or a turn cancels its goal) and
the carry fails with `grasp_lost`, naming the leaf, so `regrasp` looks where it fell at
once. The walk to put an object back is wrapped the same way (`tree.put_back_tree`).
"""

from __future__ import annotations

from collections.abc import Iterator

import py_trees
from py_trees.common import Status

from services.mission.behaviours.base import FAILURE, Context, Failure, blackboard

DETAIL = "the grasp let go while carrying the object"


class WhileHeld(py_trees.decorators.Decorator):
    def __init__(self, ctx: Context, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name=f"{child.name}_while_held", child=child)
        self.ctx = ctx
        self.bb = blackboard(self.name, (FAILURE,))

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        wbc = self.ctx.port.wbc_status()
        if wbc is None or wbc.held:
            yield from super().tick()
            return
        tip = self.decorated.tip()
        where = f" ({tip.name})" if tip is not None and tip is not self.decorated else ""
        detail = DETAIL + where
        self.bb.set(FAILURE, Failure("grasp_lost", detail, self.name, self.ctx.port.now_ns))
        self.ctx.decide(f"{self.name} failed: grasp_lost: {detail}")
        self.feedback_message = f"grasp_lost: {detail}"
        self.stop(Status.FAILURE)  # the running leaf stops: its goal is cancelled
        yield self

    def update(self) -> Status:
        return self.decorated.status
