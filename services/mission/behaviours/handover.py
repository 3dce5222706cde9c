"""The felt handover: wait until the person pulls the object, as a real robot would.

`FeelPull` holds still `settle_s` with the object presented, takes the pull detector's
baseline from `wbc/status` (gripper effort and wrench at rest), then feeds it every
status until it feels the pull: SUCCESS (the tree releases next). The grasp detector
letting go while a pull was being felt (within `handover_taken_window_s`, before the
detector's debounce) is the person taking it: SUCCESS too. Letting go with no pull →
`grasp_lost` at once (the object fell: nobody will pull).
Nobody pulls within `handover_timeout_s` → `handover_timeout`. The sim's handover event
is never read.
"""

from __future__ import annotations

from typing import Any

from py_trees.common import Status

from services.mission.behaviours.base import Context, MissionBehaviour


class FeelPull(MissionBehaviour):
    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("feel_pull", ctx, stage)
        self.detector: Any = None
        self.baseline = False
        self.last_stamp = -1

    def initialise(self) -> None:
        super().initialise()
        self.detector = self.ctx.algorithms.pull_detector()
        self.baseline = False
        self.last_stamp = -1

    def update(self) -> Status:
        s = self.settings
        if self.elapsed_s() > s.handover_timeout_s:
            return self.fail(
                "handover_timeout", f"nobody took the object in {s.handover_timeout_s:.0f} s"
            )
        status = self.port.wbc_status()
        if status is None or status.stamp_ns == self.last_stamp:
            return Status.RUNNING
        self.last_stamp = status.stamp_ns
        if not status.held:
            if self.baseline and (
                self.detector.update(status)
                or self.detector.pulled_within(status.stamp_ns, s.handover_taken_window_s)
            ):
                self.ctx.decide(
                    f"handover: the object left the jaws while pulled "
                    f"({self.detector.pull_n:+.1f} N toward the person): taken"
                )
                return Status.SUCCESS
            return self.fail("grasp_lost", "the object slipped out while presenting it")
        if not self.baseline:
            if self.elapsed_s() >= s.settle_s:
                self.detector.reset(status)
                self.baseline = True
                self.ctx.decide("handover: holding still, waiting for the pull")
            self.feedback_message = "holding still"
            return Status.RUNNING
        if self.detector.update(status):
            self.ctx.decide(
                f"handover: pull felt (effort {status.gripper_effort:.2f} N·m, "
                f"force {status.gripper_wrench[:3]})"
            )
            return Status.SUCCESS
        self.feedback_message = "waiting for the pull"
        return Status.RUNNING
