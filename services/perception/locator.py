"""Serving `perception/locate`: the best current instance of a class or of a map id.

`Locator.serve(req, selector)` is the queryable's handler (called on the query server's
thread; it reads `RecentDetections`, which locks, and nothing else the loop writes). It
refuses with `RequestError`: `malformed`/`invalid` requests (`locate.check_request`),
`unavailable` while the segmenter cannot run or before any frame was processed, and,
by map id, `unavailable` when the semantic map does not answer (or the map's own error
code). Otherwise it answers with the best candidate among the detections no older than
`max_age_s` behind the newest tick (`locate.best_of_class`, or `locate.nearest_to` the
entity's mapped position within `locate_gate_m` metres, the detection then carrying the
map id), or `found=False` stamped with the newest tick.

No Zenoh: `map_entity(key)` asks the semantic map for one entity (raising `NoReply` or
`RemoteError` as `common.bus.Bus.query` does).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import msgspec

from common.bus import NoReply, RemoteError, RequestError
from common.keys import map_artifact, map_person
from common.messages.perception import LocateReply, LocateRequest
from common.messages.semantic_map import MapEntity
from services.perception.locate import RecentDetections, best_of_class, check_request, nearest_to
from services.perception.pipeline import CLASSES


class Locator:
    """The `perception/locate` queryable (see the module docstring)."""

    def __init__(
        self,
        recent: RecentDetections,
        cameras: Sequence[str],
        unavailable: str,
        gate_m: float,
        map_entity: Callable[[str], MapEntity],
    ) -> None:
        self.recent, self.cameras = recent, cameras
        self.unavailable, self.gate_m = unavailable, gate_m
        self._map_entity = map_entity

    def serve(self, req: LocateRequest | None, selector: str) -> LocateReply:
        del selector
        req = check_request(req, self.cameras, CLASSES)
        if self.unavailable:
            raise RequestError("unavailable", self.unavailable)
        if self.recent.now_ns < 0:
            raise RequestError("unavailable", "no frame processed yet")
        cands = self.recent.candidates(req.camera, req.max_age_s)
        if req.class_name is not None:
            best = best_of_class(cands, req.class_name)
        else:
            assert req.map_id is not None  # check_request: exactly one
            entity = self.entity(req.map_id)
            best = nearest_to(cands, entity.class_name, entity.position_in_world[:2], self.gate_m)
            if best is not None:
                best = (best[0], best[1], msgspec.structs.replace(best[2], map_id=req.map_id))
        if best is None:
            return LocateReply(stamp_ns=self.recent.now_ns, found=False)
        return LocateReply(stamp_ns=best[1], found=True, camera=best[0], detection=best[2])

    def entity(self, map_id: str) -> MapEntity:
        """The map's entity `map_id`; `RequestError` when the map cannot tell."""
        key = map_person(map_id) if map_id.startswith("person_") else map_artifact(map_id)
        try:
            return self._map_entity(key)
        except NoReply:
            raise RequestError(
                "unavailable", f"the semantic map does not answer {key}: cannot locate by map id"
            ) from None
        except RemoteError as exc:
            raise RequestError(exc.error.code, exc.error.message) from None
