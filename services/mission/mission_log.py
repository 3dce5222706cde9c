"""What the mission tells a person, in the service's log and in rerun, on sim time.

- `mission/request`: every request and cancel as received, and its verdict (accepted, or
  rejected with the typed reason).
- `mission/decisions`: every decision a behaviour or a recovery took, and why.
- `mission/tree`: the tree with every node's status (py_trees' unicode rendering) as a
  text document, each time any node's status changed.
- `mission/status`: the published status, each time it changed; `mission/progress` as a
  scalar.
- `mission/patrol`: the mapping patrol's requests, decisions and end; its route as
  `world/mission/patrol` (paths) and `world/mission/patrol/viewpoints`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import rerun as rr

from common.messages.base import NS_PER_S
from common.messages.mission import MissionStatus
from common.recording import is_recording, stamp
from services.mission.coverage import Route


class MissionLogger:
    def __init__(self, rec: rr.RecordingStream, log: logging.Logger) -> None:
        self.rec, self.log = rec, log
        self.on = is_recording(rec)
        self.t_ns = 0
        self._tree: tuple[tuple[str, str], ...] = ()

    def at(self, t_ns: int) -> None:
        """What follows happened at sim time t."""
        self.t_ns = t_ns
        if self.on:
            stamp(self.rec, t_ns)

    def _say(self, entity: str, level: int, text: str) -> None:
        self.log.log(level, "t=%.2f s %s", self.t_ns / NS_PER_S, text)
        if self.on:
            name = logging.getLevelName(level)
            self.rec.log(entity, rr.TextLog(text, level=name))

    def request(self, text: str, warn: bool = False) -> None:
        self._say("mission/request", logging.WARNING if warn else logging.INFO, text)

    def decision(self, text: str) -> None:
        self._say("mission/decisions", logging.INFO, text)

    def tree(self, statuses: tuple[tuple[str, str], ...], render: Callable[[], str]) -> None:
        """The tree's text, when any node's status changed since the last call."""
        if statuses == self._tree:
            return
        self._tree = statuses
        text = render()
        self.log.debug("tree at t=%.2f s:\n%s", self.t_ns / NS_PER_S, text)
        if self.on:
            self.rec.log("mission/tree", rr.TextDocument(text))

    def status(self, status: MissionStatus) -> None:
        failed = status.state in ("failed", "rejected")
        text = (
            f"{status.request_id or '-'} {status.state} {status.behaviour} "
            f"{status.progress:.0%} {status.reason} {status.detail}"
        ).rstrip()
        self._say("mission/status", logging.WARNING if failed else logging.INFO, text)
        if self.on:
            self.rec.log("mission/progress", rr.Scalars(status.progress))

    def patrol(self, text: str, warn: bool = False) -> None:
        self._say("mission/patrol", logging.WARNING if warn else logging.INFO, text)

    def route(self, route: Route) -> None:
        """The patrol's route: its paths and viewpoints (and facings), a little above the
        floor."""
        if not self.on:
            return
        self.rec.log(
            "world/mission/patrol",
            rr.LineStrips3D(
                [np.column_stack([p, np.full(len(p), 0.05)]) for p in route.paths],
                colors=(200, 60, 200),
            ),
        )
        self.rec.log(
            "world/mission/patrol/viewpoints",
            rr.Points3D([(v[0], v[1], 0.05) for v in route.viewpoints], radii=0.08),
        )
        if route.facings is not None:  # a surface pass: where each viewpoint looks
            self.rec.log(
                "world/mission/patrol/facings",
                rr.Arrows3D(
                    origins=[(v[0], v[1], 0.05) for v in route.viewpoints],
                    vectors=[(np.cos(f), np.sin(f), 0.0) for f in route.facings],
                    colors=(200, 60, 200),
                ),
            )
