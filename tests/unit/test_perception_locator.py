"""`perception/locate` served without Zenoh: refusals, by class, by map id."""

from __future__ import annotations

import pytest

from common.bus import NoReply, RemoteError, RequestError
from common.messages.errors import ErrorReply
from common.messages.perception import Detection, Detections, LocateRequest
from common.messages.semantic_map import MapEntity
from services.perception.frames import IDENTITY
from services.perception.locate import RecentDetections
from services.perception.locator import Locator
from tests.unit.mission_fakes import detection, entity

CAMERAS = ("camera_head", "camera_wrist")
T = 500_000_000


def recent(*dets: Detection, camera: str = "camera_head") -> RecentDetections:
    out = RecentDetections()
    out.put(
        Detections(
            stamp_ns=T,
            camera=camera,
            T_world_base=IDENTITY,
            segmenter="truth",
            detections=list(dets),
        )
    )
    return out


class Map:
    """The semantic map's answers by key, and the keys asked for."""

    def __init__(self, answer: MapEntity | Exception) -> None:
        self.answer = answer
        self.asked: list[str] = []

    def __call__(self, key: str) -> MapEntity:
        self.asked.append(key)
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


def locator(
    seen: RecentDetections, unavailable: str = "", answer: MapEntity | Exception | None = None
) -> tuple[Locator, Map]:
    the_map = Map(answer if answer is not None else entity("bottle_7", 2.0, 0.0))
    return Locator(seen, CAMERAS, unavailable, 0.5, the_map), the_map


def refusal(loc: Locator, req: LocateRequest | None) -> tuple[str, str]:
    with pytest.raises(RequestError) as err:
        loc.serve(req, "")
    return err.value.code, err.value.message


def test_what_cannot_be_answered_is_refused_with_a_typed_reason() -> None:
    assert refusal(locator(recent())[0], None)[0] == "malformed"
    assert refusal(locator(recent())[0], LocateRequest(class_name="cup"))[0] == "invalid"
    down = locator(recent(), unavailable="no model")[0]
    assert refusal(down, LocateRequest(class_name="bottle")) == ("unavailable", "no model")
    never = locator(RecentDetections())[0]
    assert refusal(never, LocateRequest(class_name="bottle")) == (
        "unavailable",
        "no frame processed yet",
    )


def test_by_class_the_best_current_detection_answers_and_none_is_not_found() -> None:
    loc, the_map = locator(recent(detection("bottle_1", 1.0)))
    reply = loc.serve(LocateRequest(class_name="bottle"), "")
    assert (reply.found, reply.stamp_ns, reply.camera) == (True, T, "camera_head")
    assert reply.detection is not None and reply.detection.d_obj == 1.0
    missed = loc.serve(LocateRequest(class_name="bottle", camera="camera_wrist"), "")
    assert (missed.found, missed.stamp_ns, missed.detection) == (False, T, None)
    assert the_map.asked == []


def test_by_map_id_the_detection_at_the_mapped_place_carries_the_id() -> None:
    loc, the_map = locator(recent(detection("bottle_1", 1.0), detection("bottle_2", 2.1)))
    reply = loc.serve(LocateRequest(map_id="bottle_7"), "")
    assert reply.found and reply.detection is not None
    assert (reply.detection.d_obj, reply.detection.map_id) == (2.1, "bottle_7")
    assert the_map.asked == ["dume/map/artifacts/bottle_7"]
    loc.entity("person_3")
    assert the_map.asked[-1] == "dume/map/people/person_3"


def test_a_map_that_cannot_tell_refuses_the_locate() -> None:
    silent = locator(recent(), answer=NoReply("nobody"))[0]
    code, message = refusal(silent, LocateRequest(map_id="bottle_7"))
    assert code == "unavailable" and "does not answer dume/map/artifacts/bottle_7" in message
    error = ErrorReply(code="unknown_id", message="no artifact bottle_7")
    unknown = locator(recent(), answer=RemoteError("k", error))[0]
    assert refusal(unknown, LocateRequest(map_id="bottle_7")) == (
        "unknown_id",
        "no artifact bottle_7",
    )
