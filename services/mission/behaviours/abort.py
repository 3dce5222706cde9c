"""`abort`: stop everything safely and keep the reason for the status.

`halt` is what abort and a user's cancel both do: cancel any navigation goal, command
zero velocity from `mission`, hold the arm where it is (the controller leaves
`manipulate`: joints frozen; a held object stays gripped) and put the controller in
`stand` obeying navigation (so a later mission starts from a known state). The `Abort`
leaf runs when the mission's sequence failed: it halts and returns FAILURE, the
blackboard's `failure` still saying why.
"""

from __future__ import annotations

from py_trees.common import Status

from services.mission.behaviours.base import FAILURE, Context, Failure, MissionBehaviour
from services.mission.ports import RobotPort


def halt(port: RobotPort, reason: str) -> None:
    """Cancel navigation, stop the base, hold the arm, stand."""
    port.cancel_nav("", reason)
    port.command_velocity(0.0, 0.0, 0.0)
    port.hold_arm(reason)
    port.set_mode("stand", "navigation")


class Abort(MissionBehaviour):
    def __init__(self, ctx: Context) -> None:
        super().__init__("abort", ctx, stage="")

    def update(self) -> Status:
        failure = self.get(FAILURE)
        if not isinstance(failure, Failure):
            failure = Failure("internal", "the mission failed without a reason", "", 0)
            self.set(FAILURE, failure)
        halt(self.port, f"abort: {failure.reason}")
        self.ctx.decide(f"abort: {failure.reason}: {failure.detail} (in {failure.behaviour})")
        self.feedback_message = failure.reason
        return Status.FAILURE
