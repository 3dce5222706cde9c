"""Pushing the robot from outside: the test and evaluation hook behind `dume/world/push`.

A `Push` (a force on the base for a duration) is held until the sim's step at its stamp
and then handed to `SimCore.push`, so a lockstep run with a push is as repeatable as one
without; a push that arrives after its stamp is applied at once and logged as late, a bad
one (non-finite force, duration outside (0, 10] s) is refused with a warning and the sim
goes on.
"""

from __future__ import annotations

import logging

from common import keys as K
from common.bus import Bus
from common.messages.base import NS_PER_S
from common.messages.sim import Push
from services.sim.core import PushError, SimCore
from services.sim.stamped_hook import StampedHook, late_note


class PushHook(StampedHook[Push]):
    """The pending pushes; `apply(t_ns, core)` before every step."""

    def __init__(self, bus: Bus, log: logging.Logger) -> None:
        super().__init__(bus.fifo(K.WORLD_PUSH, Push, maxlen=64), log)

    def apply(self, t_ns: int, core: SimCore) -> None:
        """Start the pushes stamped at or before t, in arrival order."""
        for push in self._due(t_ns):
            try:
                steps = core.push(push.force_in_world, push.duration_s, push.target)
            except PushError as exc:
                self.log.warning("push refused at t=%.3f s: %s", t_ns / NS_PER_S, exc)
                continue
            self.applied += 1
            self.log.info(
                "push %s N for %d steps on the %s at t=%.3f s%s",
                [round(f, 1) for f in push.force_in_world],
                steps,
                push.target,
                t_ns / NS_PER_S,
                late_note(t_ns, push.stamp_ns),
            )
