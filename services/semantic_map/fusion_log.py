"""What fusing a frame did, in the service's log (`dume.semantic_map`).

`FusionLog.fused(dets, report, smap)` is told of every camera frame the map fused (its
`IngestReport`) and logs: per camera, frames, detections fused and ignored, summed over
`SUMMARY_EVERY_S` of sim time (the frames' stamps) and then logged in one line (what
each camera adds to the map); every new entity with its place, every artifact newly
missing and every false entry deleted, each with the frame's sim time in s. Only the
map's tick thread calls it, with the map's lock held (it reads the map's tracks).
"""

from __future__ import annotations

import logging
from collections import defaultdict

import numpy as np

from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from services.semantic_map.mapper import IngestReport, SemanticMap

#: Sim seconds between the per-camera summaries of what was fused.
SUMMARY_EVERY_S = 10.0
log = logging.getLogger("dume.semantic_map")


class FusionLog:
    def __init__(self) -> None:
        #: Per camera since the last summary: frames, detections fused, ignored (logged
        #: every `SUMMARY_EVERY_S` of sim time: what each camera adds to the map).
        self.counts: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])
        self.last_summary_ns = 0

    def fused(self, dets: Detections, report: IngestReport, smap: SemanticMap) -> None:
        c = self.counts[dets.camera]
        c[0], c[1], c[2] = c[0] + 1, c[1] + report.fused, c[2] + report.ignored
        if dets.stamp_ns - self.last_summary_ns >= SUMMARY_EVERY_S * NS_PER_S:
            self.last_summary_ns = dets.stamp_ns
            log.info(
                "fused in the last %.0f s: %s",
                SUMMARY_EVERY_S,
                ", ".join(f"{cam} {f} frames {n} detections ({i} ignored)"
                          for cam, (f, n, i) in sorted(self.counts.items())),
            )  # fmt: skip
            self.counts.clear()
        for entity_id in report.new_ids:
            tr = smap.artifacts.by_id(entity_id) or smap.people.by_id(entity_id)
            if tr is not None:
                log.info(
                    "t=%.2f s: new %s at (%.2f, %.2f) from %s",
                    dets.stamp_ns / NS_PER_S,
                    entity_id,
                    tr.xy[0],
                    tr.xy[1],
                    dets.camera,
                )
        for entity_id in report.missing:
            log.info(
                "t=%.2f s: %s missing: looked at its place from %s, not seen",
                dets.stamp_ns / NS_PER_S,
                entity_id,
                dets.camera,
            )
        for entity_id, was, now, seen in report.jumps:
            log.info(
                "t=%.2f s: %s moved %.2f m on one %s detection at (%.2f, %.2f): "
                "(%.2f, %.2f) -> (%.2f, %.2f)",
                dets.stamp_ns / NS_PER_S, entity_id, float(np.linalg.norm(now - was)),
                dets.camera, seen[0], seen[1], was[0], was[1], now[0], now[1],
            )  # fmt: skip
        for entity_id, was, now, app in report.reidentified:
            log.info(
                "t=%.2f s: %s known again by their colours (distance %.2f) %.2f m from where "
                "the map had them: (%.2f, %.2f) -> (%.2f, %.2f)",
                dets.stamp_ns / NS_PER_S, entity_id, app, float(np.linalg.norm(now - was)),
                was[0], was[1], now[0], now[1],
            )  # fmt: skip
        for entity_id, seen in report.held:
            log.info(
                "t=%.2f s: %s standing: a %s detection of them at (%.2f, %.2f), far from "
                "where they are, held until a second one there",
                dets.stamp_ns / NS_PER_S, entity_id, dets.camera, seen[0], seen[1],
            )  # fmt: skip
        for entity_id, reason in report.dropped:
            t = dets.stamp_ns / NS_PER_S
            log.info("t=%.2f s: %s deleted from %s: %s", t, entity_id, dets.camera, reason)
