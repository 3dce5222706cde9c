"""The felt handover: wait until the person pulls the object, as a real robot would.

`FeelPull` holds still `settle_s` with the object presented, takes the pull detector's
baseline from `wbc/status` (gripper effort and wrench at rest), then feeds it every
status until it feels the pull: SUCCESS (the tree releases next). The grasp detector
letting go while a pull was being felt (within `handover_taken_window_s`, before the
detector's debounce) is the person taking it: SUCCESS too. Letting go with no pull →
`grasp_lost` at once (the object fell: nobody will pull).
Nobody pulls within `handover_timeout_s` → `handover_timeout`. The sim's handover event
is never read.

Leaning in: nobody pulling in the first `handover_lean_after_s` of an offer (FeelPull's
`before_lean` part fails `handover_timeout`, `NotTakenYet` forgets it), the robot holds
the object out `handover_lean_m` nearer (`LeanIn`: the base walks that far ahead on the
mission's cmd_vel, within navigation's people caps and the room ahead, at `LEAN_MPS`),
stands and feels for the pull again for the rest of the offer. The person's hand takes
what is held out within 0.25 m of it, and at the nominal handover distance that margin is
a few centimetres: hall seed 1 presented 3 cm farther and 2 cm more to the side than a
run that was taken, and nobody took it in 60 s.

The side: the robot stands in front of a person whose facing the map knows (`FACING`);
of one it only saw, it does not know which way they face, and offers on the side it came
from. Nobody pulling there within `handover_side_timeout_s`, the tree goes round them
(`next_side`): 60° either way, then 120°, then behind (`SIDE_OFFSETS_DEG`), up to
`handover_sides` sides, as a person would step round to someone's front.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Literal

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

#: m/s: how fast the base leans in (`LeanIn`); it gives up after the time at that speed
#: plus `LEAN_SLACK_S` (held back by the people caps or the room ahead).
LEAN_MPS = 0.05
LEAN_SLACK_S = 2.0

Part = Literal["all", "before_lean", "after_lean"]


class FeelPull(MissionBehaviour):
    """`part`: the whole offer's wait, or its part before or after the lean-in (the module
    docstring)."""

    def __init__(self, ctx: Context, stage: str, part: Part = "all") -> None:
        super().__init__("feel_pull" if part != "after_lean" else "feel_pull_again", ctx, stage)
        self.part = part
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
        limit = offer_s(self)
        lean = lean_due(self)
        if self.part == "before_lean" and lean:
            limit = s.handover_lean_after_s
        elif self.part == "after_lean":
            limit -= s.handover_lean_after_s
        if self.elapsed_s() > limit:
            here = "" if facing else " on this side"
            waited = limit
            if self.part == "before_lean" and lean:
                here += f": holding it out {s.handover_lean_m * 100:.0f} cm nearer"
            elif self.part == "after_lean":
                waited = offer_s(self)
                here += f", held out nearer after {s.handover_lean_after_s:.0f} s"
            return self.fail("handover_timeout", f"nobody took the object in {waited:.0f} s{here}")
        status, detector = self.port.wbc_status(), self.detector
        if status is None or detector is None or status.stamp_ns == self.last_stamp:
            return Status.RUNNING
        self.last_stamp = status.stamp_ns
        if not status.held:
            if (self.baseline and detector.update(status)) or detector.pulled_within(
                status.stamp_ns, s.handover_taken_window_s
            ):
                self.ctx.decide(
                    f"handover: the object left the jaws while pulled "
                    f"({detector.pull_n:+.1f} N toward the person, a rise of "
                    f"{detector.swing_n:.1f} N): taken"
                )
                return Status.SUCCESS
            felt = (
                f"the force toward the person rose by {detector.swing_n:.1f} N at most"
                if self.baseline
                else "the arm still settling"
            )
            if self.baseline and detector.swing_n >= 0.5 * s.pull_detector.force_n:
                felt += ", under a pull's but more than the arm's own swings: they may have it"
            return self.fail(
                "grasp_lost", f"the object slipped out while presenting it (no pull felt: {felt})"
            )
        if not self.baseline:
            detector.note(status)  # a person quick to take hold pulls while the arm settles
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


def offer_s(b: MissionBehaviour) -> float:
    """How long one offer waits for the pull: `handover_timeout_s` before a person whose
    facing is known, else `handover_side_timeout_s` on each side."""
    s = b.settings
    return s.handover_timeout_s if b.get(FACING, True) else s.handover_side_timeout_s


def lean_due(b: MissionBehaviour) -> bool:
    """Whether an offer leans in: `handover_lean_m` > 0 and the offer waits longer than
    `handover_lean_after_s` (with a second's feel after it)."""
    s = b.settings
    return s.handover_lean_m > 0.0 and offer_s(b) > s.handover_lean_after_s + s.settle_s + 1.0


class NotTakenYet(MissionBehaviour):
    """After the offer's first part (`FeelPull` `before_lean`) failed: SUCCESS, the
    failure forgotten, when nobody pulled (`handover_timeout`) and the offer leans in
    (`lean_due`). Any other failure (the object slipped out) stays a FAILURE."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("not_taken_yet", ctx, stage)

    def update(self) -> Status:
        if not lean_due(self):
            return Status.FAILURE  # the offer's whole wait is spent
        return Status.FAILURE if self.forget_failure("handover_timeout") is None else Status.SUCCESS


class LeanIn(MissionBehaviour):
    """The base walks `handover_lean_m` ahead on the mission's cmd_vel (mode walk/mission)
    at `LEAN_MPS`, within navigation's people caps and the room ahead; SUCCESS when it has,
    or after that time and `LEAN_SLACK_S` however far it got (said)."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("lean_in", ctx, stage)
        self.start: tuple[float, float] | None = None

    def initialise(self) -> None:
        super().initialise()
        self.start = self.port.robot_xy()

    def update(self) -> Status:
        want = self.settings.handover_lean_m
        here = self.port.robot_xy()
        moved = 0.0 if here is None or self.start is None else math.dist(here, self.start)
        if moved >= want or self.elapsed_s() > want / LEAN_MPS + LEAN_SLACK_S:
            self.port.command_velocity(0.0, 0.0, 0.0)
            self.ctx.decide(f"handover: leaned in {moved * 100:.0f} cm of {want * 100:.0f} cm")
            return Status.SUCCESS
        held = self.port.command_velocity(LEAN_MPS, 0.0, 0.0)
        self.feedback_message = f"leaning in{f', held back by {held}' if held else ''}"
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.port.command_velocity(0.0, 0.0, 0.0)


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
