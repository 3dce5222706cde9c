"""What the WBC does when its QP fails: keep the last torques, then the stand hold.

`QpFallback.command` sees every solved tick's command (`WbcCommand.qp_ok`):

- the first failed solve in a run passes the controller's command through (on a failure
  `WholeBodyController.step` keeps the last torques): one tick's grace;
- the second failed solve in a row engages `safety.StandHold` at the model's current
  joints, and the hold commands every tick from then on;
- in the hold, `recover_ticks` good solves in a row give control back to the QP: the
  controller is reset to the state (its references restart from where the robot is), and
  that tick's command is the QP's.

Every change is said through `say` (the node's status reason and log). Pure bookkeeping
on the WBC's thread, no lock; time is counted in ticks.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from services.wbc.arm_actions import ArmReferences
from services.wbc.model import RobotModel
from services.wbc.safety import StandHold
from services.wbc.values import WbcCommand, WbcState


class Controller(Protocol):
    """The part of `WholeBodyController` the fallback uses."""

    @property
    def model(self) -> RobotModel: ...

    def reset(self, state: WbcState) -> None: ...


class QpFallback:
    """The QP-failure state machine; `active` while the stand hold is in charge."""

    def __init__(self, ctrl: Controller, recover_ticks: int, say: Callable[[str], None]) -> None:
        self.ctrl, self.recover_ticks, self.say = ctrl, recover_ticks, say
        self.hold = StandHold()
        self.active = False
        self.fail_run = 0  # failed solves in a row
        self.ok_run = 0  # good solves in a row while active
        self.qp_failures = 0  # failed solves since start

    def command(self, cmd: WbcCommand, state: WbcState, arm: ArmReferences) -> WbcCommand:
        """The command to send for this tick's solve `cmd` (of `state`); the hold keeps the
        gripper's reference from `arm` (its effort N·m when gripping, else its angle rad)."""
        if cmd.qp_ok:
            self.fail_run = 0
            if self.active:
                self.ok_run += 1
                if self.ok_run >= self.recover_ticks:
                    self.active = False
                    self.ctrl.reset(state)
                    self.say("QP solves again: whole-body control resumed")
        else:
            self.fail_run += 1
            self.qp_failures += 1
            self.ok_run = 0
            if self.fail_run == 1:
                self.say(f"QP failed ({cmd.qp_status}): holding the last torques")
            elif not self.active:
                self.active = True
                self.hold.engage(self.ctrl.model)
                self.say(f"QP failed {self.fail_run} ticks: stand hold")
        if self.active:
            return self.hold.command(arm.gripper_effort, arm.gripper_angle)
        return cmd
