"""`perception/locate`: the best current instance of a class or of a map id.

`RecentDetections` keeps each camera's newest `Detections` (thread-safe: the node's
loop writes, the queryable's thread reads). `check_request` refuses what cannot be
answered with a typed reason; `best_of_class` picks the highest score, then the most
points, among detections no older than `max_age_s` behind the newest tick;
`nearest_to` matches a mapped position to a detection of its class within a gate
(`common.sightings`, the rule the mission's approach uses too).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

from common.bus import RequestError
from common.messages.base import NS_PER_S
from common.messages.perception import Detection, Detections, LocateRequest
from common.sightings import pick_detection

Candidate = tuple[str, int, Detection]  # camera, stamp_ns, detection


class RecentDetections:
    """Each camera's newest `Detections`, and the newest tick processed."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._by_camera: dict[str, Detections] = {}
        self.now_ns = -1

    def put(self, detections: Detections) -> None:
        with self._lock:
            self._by_camera[detections.camera] = detections
            self.now_ns = max(self.now_ns, detections.stamp_ns)

    def candidates(self, camera: str | None, max_age_s: float) -> list[Candidate]:
        """Detections of `camera` (None: any) stamped within `max_age_s` of the newest."""
        with self._lock:
            oldest = self.now_ns - round(max_age_s * NS_PER_S)
            return [
                (cam, d.stamp_ns, det)
                for cam, d in sorted(self._by_camera.items())
                if (camera is None or cam == camera) and d.stamp_ns >= oldest
                for det in d.detections
            ]


def check_request(
    req: LocateRequest | None, cameras: Sequence[str], classes: Sequence[str]
) -> LocateRequest:
    """The request if it can be answered; `RequestError("invalid", …)` saying why not."""
    if req is None:
        raise RequestError("malformed", "locate needs a LocateRequest payload")
    if (req.class_name is None) == (req.map_id is None):
        raise RequestError(
            "invalid",
            f"give exactly one of class_name and map_id, got class_name={req.class_name!r} "
            f"map_id={req.map_id!r}",
        )
    if req.class_name is not None and req.class_name not in classes:
        raise RequestError(
            "invalid", f"class {req.class_name!r} is not detected; classes are {list(classes)}"
        )
    if req.camera is not None and req.camera not in cameras:
        raise RequestError(
            "invalid", f"camera {req.camera!r} is not processed; cameras are {list(cameras)}"
        )
    if not req.max_age_s > 0:
        raise RequestError("invalid", f"max_age_s must be positive, got {req.max_age_s}")
    return req


def _rank(c: Candidate) -> tuple[float, int, int]:
    return (c[2].score, c[2].n_points, c[1])


def best_of_class(candidates: Sequence[Candidate], class_name: str) -> Candidate | None:
    """The highest-scored detection of `class_name` (then most points, then newest)."""
    matches = [c for c in candidates if c[2].class_name == class_name]
    return max(matches, key=_rank) if matches else None


def nearest_to(
    candidates: Sequence[Candidate], class_name: str, xy: tuple[float, float], gate_m: float
) -> Candidate | None:
    """The mapped thing of `class_name` at `xy` (world) among the candidates, by
    `common.sightings.pick_detection`'s rule."""
    found = pick_detection([c[2] for c in candidates], class_name, xy, gate_m)
    return next((c for c in candidates if c[2] is found), None)
