"""The speed and separation monitor's caps for what drives the base without a goal (the
mission's approach, back-off and look round): navigation publishes one per axis of the
base on `nav/status`, and the mission's cmd_vel goes out within them."""

from __future__ import annotations

import math

from common.config import PeopleSettings
from common.messages.navigation import NavStatus
from services.mission.robot import within_caps
from services.navigation.costmap import Person
from services.navigation.grid import Footprint, Pose
from services.navigation.people import base_caps

FP = Footprint.stowed()
TOP = 0.6


def _caps(pose: Pose, people: list[Person], stopped: tuple[bool, ...] = (False,) * 4) -> tuple:
    return base_caps(pose, people, FP, PeopleSettings(), TOP, stopped)


def test_a_person_standing_just_ahead_stops_the_base_ahead_and_leaves_it_free_to_back_off() -> None:
    pose = Pose(1.0, 2.0, math.pi / 2)  # facing +y
    near = Person("person_3", 1.0, 2.0 + FP.front + 0.35, velocity=(0.0, 0.0))
    ahead, behind, left, right = _caps(pose, [near])
    assert ahead.speed == 0.0 and ahead.rule == "stop" and ahead.person_id == "person_3"
    assert behind.speed > 0.0 and behind.rule != "stop"  # away: only the slow zone
    # Inside S_p at rest, sideways is not away: the trot drifts as it steps (AWAY_COS).
    assert left.rule == "stop" and right.rule == "stop"
    further = Person("person_3", 1.0, 2.0 + FP.front + 0.8, velocity=(0.0, 0.0))
    _, _, left, right = _caps(pose, [further])  # beyond S_p at rest: along them is free
    assert left.rule != "stop" and right.rule != "stop"


def test_a_person_far_behind_caps_nothing_ahead_and_one_walking_at_it_caps_ahead() -> None:
    pose = Pose(0.0, 0.0, 0.0)
    far = Person("person_1", -6.0, 0.0, velocity=(0.0, 0.0))
    assert all(not math.isfinite(c.speed) for c in _caps(pose, [far]))
    coming = Person("person_2", FP.front + 1.2, 0.0, velocity=(-1.2, 0.0))
    ahead, behind, _, _ = _caps(pose, [coming])
    assert 0.0 <= ahead.speed < 0.3  # S_p with their 1.2 m/s towards it: slow or stop
    assert behind.speed > ahead.speed


def test_a_stop_holds_until_the_person_is_clear_by_the_resume_margin() -> None:
    pose = Pose(0.0, 0.0, 0.0)
    people = PeopleSettings()
    d_stop = None
    for k in range(80):  # a person standing ahead, 0.3 → 1.1 m from the front
        d = 0.3 + 0.01 * k
        if _caps(pose, [Person("p", FP.front + d, 0.0)])[0].speed > 0.0:
            d_stop = d
            break
    assert d_stop is not None
    just_past = Person("p", FP.front + d_stop + 0.05, 0.0)
    assert _caps(pose, [just_past])[0].speed > 0.0  # a fresh look: free
    assert _caps(pose, [just_past], (True, False, False, False))[0].speed == 0.0  # held
    assert people.slow_radius_m > d_stop


def test_the_mission_command_goes_out_within_the_caps() -> None:
    caps = (0.0, 0.1, math.inf, 0.05)
    assert within_caps((0.2, 0.0, 0.3), caps) == ((0.0, 0.0, 0.0), True)  # held, no turn
    assert within_caps((0.0, 0.0, 0.3), caps) == ((0.0, 0.0, 0.0), True)  # a stop: at rest
    assert within_caps((0.0, 0.0, 0.3), (0.2, 0.1, 0.1, 0.05)) == ((0.0, 0.0, 0.3), False)
    assert within_caps((-0.2, 0.0, 0.0), caps) == ((-0.1, 0.0, 0.0), True)
    assert within_caps((-0.05, 0.3, 0.0), caps) == ((-0.05, 0.3, 0.0), False)
    assert within_caps((0.0, -0.2, 0.0), caps) == ((0.0, -0.05, 0.0), True)
    assert within_caps((0.2, 0.0, 0.0), None) == ((0.2, 0.0, 0.0), False)
    status = NavStatus(stamp_ns=0, goal_id="", state="idle")  # an older sender: no caps
    assert within_caps((0.2, 0.0, 0.0), status.caps_mps) == ((0.2, 0.0, 0.0), False)
