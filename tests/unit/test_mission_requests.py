"""Requests and statuses without Zenoh: parsing, checks against the map, the status board."""

from __future__ import annotations

import msgspec
import pytest

from common.config import load_config
from common.messages.mission import MissionRequest
from common.messages.perception import Detection
from common.sightings import pick_detection
from services.mission.algorithms import default_algorithms
from services.mission.requests import (
    Rejection,
    StatusBoard,
    check_request,
    parse_cancel,
    parse_request,
)
from tests.unit.mission_fakes import detection, entity, small_world


@pytest.mark.parametrize(
    ("payload", "request_id", "says"),
    [
        (b"not json", "", "malformed"),
        (b"[1, 2]", "", "Expected `object`"),
        (b'{"request_id": "r7", "object": 3, "person": "person_1"}', "r7", "$.object"),
        (b'{"request_id": "r8", "object": "bottle_1"}', "r8", "person"),
        (b'{"request_id": "r9", "object": "Bottle 1!", "person": "person_1"}', "r9", "$.object"),
        (b'{"request_id": "", "object": "bottle_1", "person": "person_1"}', "", "request_id"),
        (b'{"request_id": 5, "object": "bottle_1", "person": "person_1"}', "", "request_id"),
        (b'{"request_id": "r", "object": "bottle_1", "person": "p_1", "x": 1}', "r", "x"),
        # nested past any parser's depth (the probe's RecursionError lost the tick)
        (b"[" * 100_000 + b"]" * 100_000, "", "Expected `object`"),
        (b'{"a":' * 100_000 + b"1" + b"}" * 100_000, "", "unknown field `a`"),
        (b'{"request_id": "r3", "x":' + b"[" * 100_000 + b"]" * 100_000 + b"}", "", "`x`"),
        # an id with control characters would forge log lines: refused, echoed without them
        (
            b'{"request_id": "r4\\n2026 mission INFO forged\\u0000", "object": "bottle_1", '
            b'"person": "person_1"}',
            "r42026 mission INFO forged",
            "request_id",
        ),
    ],
)
def test_a_malformed_request_is_rejected_with_its_id_when_it_has_one(
    payload: bytes, request_id: str, says: str
) -> None:
    parsed = parse_request(payload)
    assert isinstance(parsed, Rejection)
    assert (parsed.request_id, parsed.reason) == (request_id, "malformed")
    assert says in parsed.detail or says == "malformed"


def test_a_well_formed_request_parses() -> None:
    parsed = parse_request(b'{"request_id": "r1", "object": "bottle", "person": "person_1"}')
    assert parsed == MissionRequest(request_id="r1", object="bottle", person="person_1")


@pytest.mark.parametrize(
    ("obj", "person", "reason"),
    [
        ("bottle_1", "person_1", None),
        ("bottle", "person_1", None),
        ("bottle", "person", None),
        ("bottle_2", "person_1", "unknown_object"),
        ("can", "person_1", "unknown_object"),
        ("person_1", "person_1", "unknown_object"),
        ("bottle_1", "person_2", "unknown_person"),
        ("bottle_1", "bottle_1", "unknown_person"),
    ],
)
def test_requests_are_checked_against_the_map(obj: str, person: str, reason: str | None) -> None:
    robot = small_world()
    rejection = check_request(MissionRequest(request_id="r", object=obj, person=person), robot)
    assert (rejection.reason if rejection else None) == reason


def test_a_request_while_the_map_is_down_is_rejected_as_unavailable() -> None:
    robot = small_world(map_up=False)
    rejection = check_request(
        MissionRequest(request_id="r", object="bottle_1", person="person_1"), robot
    )
    assert rejection is not None and rejection.reason == "unavailable"


def test_a_class_with_only_missing_instances_is_unknown() -> None:
    e = entity("bottle_1", 1.0, 0.0)
    fields = {f: getattr(e, f) for f in e.__struct_fields__}
    robot = small_world(artifacts={"bottle_1": type(e)(**{**fields, "missing_since_ns": 1})})
    rejection = check_request(
        MissionRequest(request_id="r", object="bottle", person="person_1"), robot
    )
    assert rejection is not None and rejection.reason == "unknown_object"


def test_cancels_parse_or_are_ignored() -> None:
    assert parse_cancel(b'{"request_id": "r1", "reason": "no"}') is not None
    assert parse_cancel(b'{"reason": "no"}') is None
    assert parse_cancel(b"\xff") is None


def test_the_status_board_publishes_on_change_and_periodically() -> None:
    board = StatusBoard(every_ns=1_000_000_000)
    assert board.due(0)
    board.sent(0)
    assert not board.due(500_000_000)
    assert board.update(50, "r1", "running", "navigate_to_object", 0.1)
    assert not board.update(100, "r1", "running", "navigate_to_object", 0.101)
    assert board.update(150, "r1", "running", "approach_object", 1 / 6)
    assert board.due(1_000_000_000)
    status = board.sent(1_000_000_000)
    assert (status.stamp_ns, status.request_id, status.behaviour) == (
        1_000_000_000, "r1", "approach_object",
    )  # fmt: skip


def test_the_real_algorithms_bind_with_config_overrides() -> None:
    settings = load_config(["mission.approach_gains.k_d=0.5"]).mission
    algorithms = default_algorithms(settings)
    controller = algorithms.approacher()
    assert controller.gains.k_d == 0.5  # type: ignore[attr-defined]
    controller.reset(0.0)
    step = controller.step(0.1, algorithms.sighting(1.5, 0.0, 0.05))
    assert step.state in ("tracking", "arrived")
    assert algorithms.pull_detector() is not None


def _seen(cls: str, x: float, y: float, d_obj: float) -> Detection:
    return msgspec.structs.replace(
        detection(f"{cls}_1", d_obj), centroid_in_world=(x, y, 0.8), map_id=None
    )


def test_the_target_is_the_detection_of_its_class_at_its_mapped_place() -> None:
    box = _seen("box", 5.05, 0.10, 1.07)  # the box, at its mapped place
    edge = _seen("box", 4.45, 0.05, 1.67)  # a table edge read as a box, behind it
    can = _seen("can", 5.06, 0.08, 1.07)  # the box read as a can
    assert pick_detection([edge, box, can], "box", (5.06, 0.08), 0.35) is box
    # the box missed in this frame: the edge is not taken for it
    assert pick_detection([edge, can], "box", (5.06, 0.08), 0.35) is None
    # … but for the approach, the can at the box's place is the box
    assert pick_detection([edge, can], "box", (5.06, 0.08), 0.35, any_class=True) is can
    # no mapped place (dropped on the way): the nearest of the class to the base
    assert pick_detection([edge, box], "box", None, 0.35) is box
    assert pick_detection([], "box", None, 0.35) is None
