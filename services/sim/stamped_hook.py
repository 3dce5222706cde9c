"""What the sim's test hooks share: messages of one key held until the step at their stamp.

A test or an evaluation publishes a `Push` or a `PersonCommand` ahead of its stamp (sim
ns); the sim takes it at its step at that stamp, so a lockstep run with it is as
repeatable as one without. One that arrives after its stamp is taken at once, and the log
says how late it was. Read from the sim's loop thread (the `Fifo` is filled by Zenoh's).
"""

from __future__ import annotations

import logging
from typing import Generic, TypeVar

from common.bus import Fifo
from common.lockstep import Stamped

M = TypeVar("M", bound=Stamped)


class StampedHook(Generic[M]):
    """The pending messages of one key; `applied` counts those a subclass applied."""

    def __init__(self, fifo: Fifo[M], log: logging.Logger) -> None:
        self._fifo = fifo
        self._pending: list[M] = []
        self.log = log
        self.applied = 0

    def _due(self, t_ns: int) -> list[M]:
        """Take the messages stamped at or before t, in arrival order."""
        self._pending.extend(self._fifo.drain())
        if not self._pending:
            return []
        due = [m for m in self._pending if m.stamp_ns <= t_ns]
        self._pending = [m for m in self._pending if m.stamp_ns > t_ns]
        return due


def late_note(t_ns: int, stamp_ns: int) -> str:
    """The log's note on a message taken at t after its stamp ("" when on time)."""
    late_ms = (t_ns - stamp_ns) / 1e6
    return f" ({late_ms:.0f} ms late: it arrived after its stamp)" if late_ms > 0 else ""
