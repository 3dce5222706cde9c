"""What the map shows in rerun: entities as labelled points sized by their uncertainty,
missing artifacts in red, people's usual places (flat discs on the floor, sized by how
often they were seen there), the occupancy grid's occupied cells (static grey, learned
orange). The patrol's route is the mission's (`mission_log`)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from common.messages.base import NS_PER_S
from common.messages.semantic_map import MapEntity
from common.recording import is_recording
from services.semantic_map.mapper import SemanticMap

ARTIFACT = (40, 160, 255)
PERSON = (60, 200, 90)
MISSING = (230, 40, 40)
#: A usual place's disc: its radius grows with the square root of its sightings (m).
PLACE_RADIUS_M = 0.05


class MapLogger:
    def __init__(self, rec: rr.RecordingStream, every_s: float, grid_every_s: float) -> None:
        self.rec = rec
        self.every_ns = round(every_s * NS_PER_S)
        self.grid_every_ns = round(grid_every_s * NS_PER_S)

    def log(self, t_ns: int, smap: SemanticMap) -> None:
        if not is_recording(self.rec):
            return
        if t_ns % self.every_ns == 0:
            for kind, path, colour in (
                ("artifact", "world/map/artifacts", ARTIFACT),
                ("person", "world/map/people", PERSON),
            ):
                es = smap.entities(kind)  # type: ignore[arg-type]
                self.rec.log(
                    path,
                    rr.Points3D(
                        [e.position_in_world for e in es] or np.zeros((0, 3)),
                        radii=[max(e.uncertainty_m, 0.03) for e in es],
                        labels=[e.id for e in es],
                        colors=[MISSING if e.missing_since_ns is not None else colour for e in es],
                        show_labels=True,
                    ),
                )
                if kind == "person":
                    self._places(es)
        if t_ns % self.grid_every_ns == 0:
            occ = smap.occupancy
            learned = occ.learned_mask()
            for name, mask, colour in (
                ("static", occ.static_occupied, (150, 150, 150)),
                ("learned", learned, (255, 140, 0)),
            ):
                iy, ix = np.nonzero(mask)
                xyz = np.stack(
                    [
                        occ.origin_xy[0] + (ix + 0.5) * occ.resolution_m,
                        occ.origin_xy[1] + (iy + 0.5) * occ.resolution_m,
                        np.full(len(ix), 0.01),
                    ],
                    axis=1,
                )
                self.rec.log(
                    f"world/map/occupancy/{name}",
                    rr.Points3D(xyz, radii=occ.resolution_m / 2, colors=colour),
                )

    def _places(self, people: list[MapEntity]) -> None:
        """Every person's usual places, under their id."""
        for e in people:
            if not e.places:
                continue
            self.rec.log(
                f"world/map/places/{e.id}",
                rr.Points3D(
                    [(p.xy[0], p.xy[1], 0.02) for p in e.places],
                    radii=[PLACE_RADIUS_M * float(np.sqrt(p.sightings)) for p in e.places],
                    colors=PERSON,
                ),
            )
