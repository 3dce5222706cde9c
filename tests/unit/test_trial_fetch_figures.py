"""The fetch trial's truth probes, on a made-up run: the approach error from the
trajectory, the pull felt against the object taken, held after the pick; and which
request it makes."""

from __future__ import annotations

import math

import pytest

from bench.eval.judge import MissionRecord
from bench.eval.targets import Pair
from bench.trial_fetch import approach_errors, handover_figures, held_after_pick, request_ids
from common import robot
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.sim import HandoverTaken
from common.messages.wbc import GoalStatus, WbcStatus
from common.messages.world import Artifact, Cylinder
from services.sim.world import generate_world

S = 1_000_000_000


def _status(t_s: float, goals: list[GoalStatus], held: bool = True) -> WbcStatus:
    return WbcStatus(
        stamp_ns=round(t_s * S), mode="manipulate", cmd_vel_source="mission", goals=goals,
        base_error_m=0.0, gripper_error_m=0.0, gripper_error_rad=0.0, qp_time_us=0.0,
        qp_failures=0, contacts=(True, True, True, True), gripper_angle=0.0,
        gripper_effort=-2.0, held=held, gripper_wrench=(0.0, 0.0, -3.0, 0.0, 0.0, 0.0),
    )  # fmt: skip


def _record(stages: list[tuple[float, str]]) -> MissionRecord:
    rec = MissionRecord(request=MissionRequest(request_id="r", object="bottle_1", person="p"),
                        start_ns=0)  # fmt: skip
    rec.changes = [
        MissionStatus(stamp_ns=round(t * S), request_id="r", state="running", behaviour=b)
        for t, b in stages
    ]
    return rec


BOTTLE = Artifact(
    id="bottle_1", object_class="bottle", position=(2.0, 0.0, 0.8), yaw=0.0,
    shape=Cylinder(radius=0.03, height=0.2), mass=0.3, rgba=(1.0, 1.0, 1.0, 1.0),
    surface_id="table_1",
)  # fmt: skip


def test_the_approach_error_is_the_true_objects_offset_from_the_base_when_it_ended() -> None:
    rec = _record([(0.0, "approach_object"), (5.0, "pose_estimation")])
    x = 2.0 - robot.D_OPT_M - 0.05  # 5 cm too close, facing it
    rec.trajectory = [(1.0 * S, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0),
                      (5.0 * S, x, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0)]  # fmt: skip
    out = approach_errors(rec, BOTTLE)
    assert out["truth_d_err_m"] == pytest.approx(0.05, abs=1e-4)
    assert out["truth_theta_err_deg"] == pytest.approx(math.degrees(-robot.THETA_OPT_RAD), abs=1e-2)


def test_the_pull_is_felt_at_the_new_release_goal_not_at_the_jaws_opened_for_the_pick() -> None:
    rec = _record([(0.0, "pick_object"), (10.0, "bring_to_user"), (20.0, "release_object")])
    rec.events = [HandoverTaken(stamp_ns=24 * S, person_id="person_1", object_id="bottle_1")]
    opened = GoalStatus(goal_id="g1", kind="release", state="succeeded")
    samples = [_status(t, [opened]) for t in (5.0, 15.0, 21.0, 23.9, 24.0)]
    samples += [_status(24.3, [opened, GoalStatus(goal_id="g9", kind="release", state="active")])]
    figures, window = handover_figures(rec, samples)
    assert figures == {"pull_felt_s": 24.3, "taken_s": 24.0, "felt_after_taken_s": 0.3}
    assert [w["stamp_ns"] for w in window] == [21 * S, round(23.9 * S), 24 * S, round(24.3 * S)]
    assert [w["taken"] for w in window] == [False, False, True, True]
    assert held_after_pick(rec, samples)
    assert not held_after_pick(rec, [_status(15.0, [], held=False)])


def test_the_request_is_the_one_asked_else_the_worlds_own_pair() -> None:
    """Asked ids win (a shift's failing pair looked at again); else the small world's
    bottle_1 for person_1, a hall's `dume eval` pair; an id the world lacks is refused."""
    hall, small = generate_world(5, "hall"), generate_world(0, "small")
    seeded = lambda: Pair("bottle_1", "person_1", 2.0)  # noqa: E731
    assert request_ids(hall, seeded, ("box_1", "person_5")) == ("box_1", "person_5")
    assert request_ids(hall, seeded) == ("bottle_1", "person_1")
    assert request_ids(hall, seeded, ("box_1", "")) == ("box_1", "person_1")
    assert request_ids(small, lambda: pytest.fail("the small world has its own pair"))[0] == (
        "bottle_1"
    )
    with pytest.raises(ValueError, match="no artifact can_9 in hall seed 5"):
        request_ids(hall, seeded, ("can_9", "person_5"))
    with pytest.raises(ValueError, match="no person person_99"):
        request_ids(hall, seeded, ("box_1", "person_99"))
