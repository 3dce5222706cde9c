"""Moving people from outside: the test and evaluation hook behind `dume/world/people_command`.

A `PersonCommand` (teleport, a walk through given points, ignore the robot) is held until
the sim's step at its stamp and then handed to `People.command`, so a lockstep run with
people commands is as repeatable as one without; a command that arrives after its stamp
is applied at once and logged as late, a bad one (unknown person, bad speed) is refused
with a warning and the sim goes on.
"""

from __future__ import annotations

import logging

from common import keys as K
from common.bus import Bus
from common.messages.base import NS_PER_S
from common.messages.sim import PersonCommand
from services.sim.people import People
from services.sim.stamped_hook import StampedHook, late_note


class PeopleHook(StampedHook[PersonCommand]):
    """The pending people commands; `apply(t_ns, people)` before every step."""

    def __init__(self, bus: Bus, log: logging.Logger) -> None:
        super().__init__(bus.fifo(K.WORLD_PEOPLE_COMMAND, PersonCommand, maxlen=64), log)

    def apply(self, t_ns: int, people: People) -> None:
        """Apply the commands stamped at or before t, in stamp order."""
        for c in sorted(self._due(t_ns), key=lambda c: c.stamp_ns):
            try:
                people.command(
                    c.person_id,
                    c.position,
                    c.yaw,
                    [(p[0], p[1]) for p in c.walk_to],
                    c.speed,
                    c.ignore_robot,
                )
            except (KeyError, ValueError) as exc:
                self.log.warning("people command refused at t=%.3f s: %s", t_ns / NS_PER_S, exc)
                continue
            self.applied += 1
            self.log.info(
                "people command at t=%.3f s: %s to %s, walk %s at %.2f m/s%s%s",
                t_ns / NS_PER_S,
                c.person_id,
                c.position,
                [tuple(round(v, 2) for v in p) for p in c.walk_to],
                c.speed,
                ", ignoring the robot" if c.ignore_robot else "",
                late_note(t_ns, c.stamp_ns),
            )
