"""The shift's plots: one rerun recording per world beside the report
(`shift-seed-<seed>.rrd`; `rerun shift-seed-0.rrd`), on the `sim_time` timeline.

- `shift/separation/d_m` and `…/protective_m`: at every truth sample (the lidar's rate)
  the separation of the person whose margin is least and the protective separation S_p
  for them (both true speeds, the monitor's rule: `bench.separation`); the robot broke
  the rule where d falls below S_p while it moved towards them. `…/slow_zone_m`: the slow
  zone's radius (the settings'), the zone the robot slows in. `shift/speed_mps`: the
  base's speed.
- `shift/stage`: the request's stage by time (1 … 6 in `common.messages.mission.STAGES`'
  order, the status' `behaviour`; 0 between requests; a failure drops it to −1), and
  `shift/requests` every status change as text (the request, state, stage, reason).
- `shift/map/within_10cm` and `shift/map/current`: the map's accuracy at each request
  (`map_accuracy`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rerun as rr

from common.messages.mission import STAGES, MissionStatus
from common.messages.semantic_map import MapEntity

#: m: a map entry this close to where its artifact stands is right (the eval's 10 cm).
WITHIN_M = 0.10
#: m: a map entry farther than this from any artifact of its class that is there is stale.
STALE_M = 0.5


def map_accuracy(
    entities: Sequence[MapEntity], where: Mapping[str, tuple[float, float, float]]
) -> tuple[float, float]:
    """(within, current): the share of the artifacts there (truth: id → position) that
    the map has within `WITHIN_M` (an entry of their class), and the share of the map's
    entries not marked missing that stand within `STALE_M` of an artifact of their class
    that is there (1.0 when there is none to count)."""

    def cls(name: str) -> str:
        return name.split("_")[0]

    listed = [e for e in entities if e.missing_since_ns is None]

    def near(e: MapEntity, p: tuple[float, float, float]) -> float:
        return math.dist(e.position_in_world[:2], p[:2])

    within = [
        any(e.class_name == cls(a) and near(e, p) <= WITHIN_M for e in listed)
        for a, p in where.items()
    ]
    current = [
        any(cls(a) == e.class_name and near(e, p) <= STALE_M for a, p in where.items())
        for e in listed
    ]
    return (
        sum(within) / len(within) if within else 1.0,
        sum(current) / len(current) if current else 1.0,
    )


@dataclass
class ShiftPlots:
    """What one world's shift plots (filled as it runs, written at its end)."""

    slow_zone_m: float
    changes: list[MissionStatus] = field(default_factory=list)
    #: (t s, within, current) at each request.
    accuracy: list[tuple[float, float, float]] = field(default_factory=list)

    def write(self, path: Path, series: Sequence[tuple[float, float, float, float]]) -> None:
        """The recording at `path`, with the separation `series` (t s, d, S_p, speed)."""
        rec = rr.RecordingStream("dume_shift")
        rec.save(path)
        if series:
            cols = np.asarray(series, dtype=float)
            t = rr.TimeColumn("sim_time", duration=cols[:, 0])
            for name, k in (("separation/d_m", 1), ("separation/protective_m", 2),
                            ("speed_mps", 3)):  # fmt: skip
                rec.send_columns(f"shift/{name}", indexes=[t],
                                 columns=rr.Scalars.columns(scalars=cols[:, k]))  # fmt: skip
            zone = np.full(len(cols), self.slow_zone_m)
            rec.send_columns("shift/separation/slow_zone_m", indexes=[t],
                             columns=rr.Scalars.columns(scalars=zone))  # fmt: skip
        for c in self.changes:
            rec.set_time("sim_time", duration=c.stamp_ns / 1e9)
            stage = STAGES.index(c.behaviour) + 1 if c.behaviour in STAGES else 0
            if c.state == "failed":
                stage = -1
            elif c.state in ("succeeded", "cancelled", "rejected"):
                stage = 0
            rec.log("shift/stage", rr.Scalars(float(stage)))
            rec.log("shift/requests", rr.TextLog(
                f"{c.request_id} {c.state} {c.behaviour} {c.reason} {c.detail}".strip(),
                level="WARN" if c.state == "failed" else "INFO",
            ))  # fmt: skip
        for t_s, within, current in self.accuracy:
            rec.set_time("sim_time", duration=t_s)
            rec.log("shift/map/within_10cm", rr.Scalars(within))
            rec.log("shift/map/current", rr.Scalars(current))
        rec.flush()
