"""Moving things from outside: the test and evaluation hooks behind
`dume/world/artifact_command` (the changing hall: a part moved from bench to bench, out of
sight, or away) and `dume/world/movable_command` (a trolley left in an aisle).

An `ArtifactCommand` is held until the sim's step at its stamp and then handed to
`SimCore.place_artifact`, a `MovableCommand` to `SimCore.place_movable`, so a lockstep
run with them is as repeatable as one without; each move is a world event
(`ArtifactMoved`, `MovableMoved`: truth, where it now stands) for the evaluation. A
command that arrives after its stamp is applied at once and logged as late; a bad one
(unknown id, no place and not away, a place off the floor) is refused with a warning and
the sim goes on.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from typing import Generic, TypeVar

from common import keys as K
from common.bus import Bus
from common.messages.base import NS_PER_S
from common.messages.sim import ArtifactCommand, ArtifactMoved, MovableCommand, MovableMoved
from services.sim.core import SimCore
from services.sim.stamped_hook import StampedHook, late_note

M = TypeVar("M", ArtifactCommand, MovableCommand)
E = TypeVar("E", ArtifactMoved, MovableMoved)


class _MoveHook(StampedHook[M], ABC, Generic[M, E]):
    """A hook whose commands move one thing each: `apply` takes those due, in stamp order,
    has `_move` apply each (KeyError, ValueError: refused with a warning), and returns the
    events of those applied."""

    what = "command"

    def apply(self, t_ns: int, core: SimCore) -> list[E]:
        """Apply the commands stamped at or before t, in stamp order; what moved."""
        moved: list[E] = []
        for c in sorted(self._due(t_ns), key=lambda c: c.stamp_ns):
            try:
                event, said = self._move(t_ns, c, core)
            except (KeyError, ValueError) as exc:
                self.log.warning("%s refused at t=%.3f s: %s", self.what, t_ns / NS_PER_S, exc)
                continue
            self.applied += 1
            moved.append(event)
            self.log.info("%s at t=%.3f s: %s%s", self.what, t_ns / NS_PER_S, said,
                          late_note(t_ns, c.stamp_ns))  # fmt: skip
        return moved

    @abstractmethod
    def _move(self, t_ns: int, c: M, core: SimCore) -> tuple[E, str]:
        """Apply one command: its event and how the log says it (KeyError, ValueError:
        refused)."""


class ArtifactHook(_MoveHook[ArtifactCommand, ArtifactMoved]):
    """The pending artifact commands; `apply(t_ns, core)` before every step, the moves."""

    what = "artifact command"

    def __init__(self, bus: Bus, log: logging.Logger) -> None:
        super().__init__(bus.fifo(K.WORLD_ARTIFACT_COMMAND, ArtifactCommand, maxlen=64), log)

    def _move(self, t_ns: int, c: ArtifactCommand, core: SimCore) -> tuple[ArtifactMoved, str]:
        if c.position is None and not c.away:
            raise ValueError("a move needs a position, or away")
        where = core.place_artifact(c.artifact_id, None if c.away else c.position, c.yaw)
        said = "taken away" if c.away else f"moved to {tuple(round(v, 3) for v in where)}"
        event = ArtifactMoved(stamp_ns=t_ns, object_id=c.artifact_id, position_in_world=where,
                              away=c.away)  # fmt: skip
        return event, f"{c.artifact_id} {said}"


class MovableHook(_MoveHook[MovableCommand, MovableMoved]):
    """The pending movable commands; `apply(t_ns, core)` before every step, the moves."""

    what = "movable command"

    def __init__(self, bus: Bus, log: logging.Logger) -> None:
        super().__init__(bus.fifo(K.WORLD_MOVABLE_COMMAND, MovableCommand, maxlen=64), log)

    def _move(self, t_ns: int, c: MovableCommand, core: SimCore) -> tuple[MovableMoved, str]:
        if c.position is None and not c.away:
            raise ValueError("a move needs a position, or away")
        where = core.place_movable(c.movable_id, None if c.away else c.position, c.yaw)
        said = "parked away" if c.away else f"left at {tuple(round(v, 3) for v in where)}"
        event = MovableMoved(stamp_ns=t_ns, movable_id=c.movable_id, position_in_world=where,
                             yaw=c.yaw, away=c.away)  # fmt: skip
        return event, f"{c.movable_id} {said}"
