"""Moving artifacts from outside: the test and evaluation hook behind
`dume/world/artifact_command` (the changing hall: a part moved from bench to bench, out of
sight, or away).

An `ArtifactCommand` is held until the sim's step at its stamp and then handed to
`SimCore.place_artifact`, so a lockstep run with it is as repeatable as one without; the
move is a world event (`ArtifactMoved`, truth: where it now rests) for the evaluation. A
command that arrives after its stamp is applied at once and logged as late; a bad one
(unknown artifact, no place and not away) is refused with a warning and the sim goes on.
"""

from __future__ import annotations

import logging

from common import keys as K
from common.bus import Bus
from common.messages.base import NS_PER_S
from common.messages.sim import ArtifactCommand, ArtifactMoved
from services.sim.core import SimCore
from services.sim.stamped_hook import StampedHook, late_note


class ArtifactHook(StampedHook[ArtifactCommand]):
    """The pending artifact commands; `apply(t_ns, core)` before every step, the moves."""

    def __init__(self, bus: Bus, log: logging.Logger) -> None:
        super().__init__(bus.fifo(K.WORLD_ARTIFACT_COMMAND, ArtifactCommand, maxlen=64), log)

    def apply(self, t_ns: int, core: SimCore) -> list[ArtifactMoved]:
        """Apply the commands stamped at or before t, in stamp order; what moved."""
        moved: list[ArtifactMoved] = []
        for c in sorted(self._due(t_ns), key=lambda c: c.stamp_ns):
            try:
                if c.position is None and not c.away:
                    raise ValueError("a move needs a position, or away")
                where = core.place_artifact(c.artifact_id, None if c.away else c.position, c.yaw)
            except (KeyError, ValueError) as exc:
                self.log.warning("artifact command refused at t=%.3f s: %s", t_ns / NS_PER_S, exc)
                continue
            self.applied += 1
            moved.append(ArtifactMoved(stamp_ns=t_ns, object_id=c.artifact_id,
                                       position_in_world=where, away=c.away))  # fmt: skip
            self.log.info(
                "artifact command at t=%.3f s: %s %s%s",
                t_ns / NS_PER_S,
                c.artifact_id,
                "taken away" if c.away else f"moved to {tuple(round(v, 3) for v in where)}",
                late_note(t_ns, c.stamp_ns),
            )
        return moved
