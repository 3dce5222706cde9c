"""The felt handover: wait until the person pulls the object, as a real robot would.

`FeelPull` holds still `settle_s` with the object presented, takes the pull detector's
baseline from `wbc/status` (gripper effort and wrench at rest), then feeds it every
status until it feels the pull: SUCCESS (the tree releases next). The grasp detector
letting go while a pull was being felt (within `handover_taken_window_s`, before the
detector's debounce) is the person taking it: SUCCESS too. Letting go with no pull →
`grasp_lost` at once (the object fell: nobody will pull).
Nobody pulls within `handover_timeout_s` → `handover_timeout`. The sim's handover event
is never read.

The side: the robot stands in front of a person whose facing the map knows (`FACING`);
of one it only saw, it does not know which way they face, and offers on the side it came
from. Nobody pulling there within `handover_side_timeout_s`, the tree goes round them
(`next_side`): 60° either way, then 120°, then behind (`SIDE_OFFSETS_DEG`), up to
`handover_sides` sides, as a person would step round to someone's front.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from py_trees.common import Status

from services.mission.algorithms import PullFeeler
from services.mission.behaviours.base import (
    FACING,
    PERSON,
    SIDE,
    Context,
    MissionBehaviour,
    read,
)


class FeelPull(MissionBehaviour):
    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("feel_pull", ctx, stage)
        self.detector: PullFeeler | None = None
        self.baseline = False
        self.last_stamp = -1

    def initialise(self) -> None:
        super().initialise()
        self.detector = self.ctx.algorithms.pull_detector()
        self.baseline = False
        self.last_stamp = -1

    def update(self) -> Status:
        s = self.settings
        facing = bool(self.get(FACING, True))
        limit = s.handover_timeout_s if facing else s.handover_side_timeout_s
        if self.elapsed_s() > limit:
            here = "" if facing else " on this side"
            return self.fail("handover_timeout", f"nobody took the object in {limit:.0f} s{here}")
        status, detector = self.port.wbc_status(), self.detector
        if status is None or detector is None or status.stamp_ns == self.last_stamp:
            return Status.RUNNING
        self.last_stamp = status.stamp_ns
        if not status.held:
            if self.baseline and (
                detector.update(status)
                or detector.pulled_within(status.stamp_ns, s.handover_taken_window_s)
            ):
                self.ctx.decide(
                    f"handover: the object left the jaws while pulled "
                    f"({detector.pull_n:+.1f} N toward the person): taken"
                )
                return Status.SUCCESS
            return self.fail("grasp_lost", "the object slipped out while presenting it")
        if not self.baseline:
            if self.elapsed_s() >= s.settle_s:
                detector.reset(status)
                self.baseline = True
                f = status.gripper_wrench[:3]
                self.ctx.decide(
                    f"handover: holding still, waiting for the pull (the wrench at rest "
                    f"({f[0]:+.2f}, {f[1]:+.2f}, {f[2]:+.2f}) N, effort "
                    f"{status.gripper_effort:.2f} N·m)"
                )
            self.feedback_message = "holding still"
            return Status.RUNNING
        if detector.update(status):
            since = detector.rising_since_ns
            rising = f", rising for {(status.stamp_ns - since) / 1e9:.2f} s" if since else ""
            f = status.gripper_wrench[:3]
            self.ctx.decide(
                f"handover: pull felt ({detector.pull_n:+.1f} N toward the person{rising}, "
                f"{detector.across_n:.1f} N across; effort change "
                f"{detector.effort_change_nm:.2f} N·m, force ({f[0]:+.2f}, {f[1]:+.2f}, "
                f"{f[2]:+.2f}) N)"
            )
            return Status.SUCCESS
        self.feedback_message = "waiting for the pull"
        return Status.RUNNING


#: The sides tried round a person whose facing is unknown, from the first (deg).
SIDE_OFFSETS_DEG = (0.0, 60.0, -60.0, 120.0, -120.0, 180.0)


def side_bearing(side: tuple[float, int] | None) -> float | None:
    """The bearing (from the person) of try k round them; None before the search."""
    if side is None:
        return None
    first, k = side
    return math.remainder(first + math.radians(SIDE_OFFSETS_DEG[k]), math.tau)


class FirstSide(MissionBehaviour):
    """SUCCESS at the side the robot came to (no search yet); FAILURE once going round."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("first_side", ctx, stage)

    def update(self) -> Status:
        return Status.SUCCESS if self.get(SIDE) is None else Status.FAILURE


def next_side(ctx: Context, bb: Any) -> Callable[[Any], bool]:
    """The handover's `Recover.prepare`: the next side round a person whose facing is
    unknown (False: their facing is known, the sides are spent, or no pose to go from)."""

    def prepare(_failure: Any) -> bool:
        if read(bb, FACING, True):
            return False
        side = read(bb, SIDE)
        if side is None:
            person = ctx.port.person(str(read(bb, PERSON)))
            here = ctx.port.robot_xy()
            if person is None or here is None:
                return False
            px, py = person.position_in_world[0], person.position_in_world[1]
            side = (math.atan2(here[1] - py, here[0] - px), 0)
        k = side[1] + 1
        if k >= min(ctx.settings.handover_sides, len(SIDE_OFFSETS_DEG)):
            return False
        bb.set(SIDE, (side[0], k))
        ctx.decide(
            f"handover: going round the person, side {k + 1} "
            f"({SIDE_OFFSETS_DEG[k]:+.0f}° from the first)"
        )
        return True

    return prepare
