"""The protective separation distance of ISO/TS 15066."""

from __future__ import annotations

import dataclasses

import pytest

from bench.separation import truth_separation
from services.navigation.separation import (
    SeparationParams,
    allowed_speed,
    directed_speed,
    protective_distance,
)

P = SeparationParams(
    reaction_s=0.3, decel_mps2=0.5, intrusion_m=0.25, detection_uncertainty_m=0.1,
    robot_uncertainty_m=0.05, speed_margin_mps=0.15, unknown_speed_mps=1.6,
)  # fmt: skip


def test_the_protective_distance_is_the_standards_sum_of_its_terms() -> None:
    """S_p = v_h (T_r + T_s) + v_r T_r + v_r²/(2a) + C + Z_d + Z_r, T_s = v_r / a: a robot
    at 0.5 m/s and a person at 1.0 m/s towards each other (by hand: 1.3 + 0.15 + 0.25 +
    0.4 = 2.1 m)."""
    v_r, v_h = 0.5, 1.0
    by_hand = v_h * (0.3 + 1.0) + v_r * 0.3 + v_r**2 / 1.0 + 0.4
    assert protective_distance(v_r, v_h, P) == pytest.approx(by_hand) == pytest.approx(2.1)
    assert protective_distance(0.0, 0.0, P) == pytest.approx(P.fixed_m) == pytest.approx(0.4)
    assert protective_distance(-1.0, -1.0, P) == protective_distance(0.0, 0.0, P)


def test_the_monitors_lead_counts_with_the_reaction_time_and_the_judge_has_none() -> None:
    """With a lead of 0.4 s the travel terms run over T_r + 0.4 s: the separation the
    standard asks for 0.4 s from now. The truth judge takes the standard's own."""
    led = dataclasses.replace(P, lead_s=0.4)
    v_r, v_h = 0.5, 1.0
    by_hand = v_h * (0.7 + 1.0) + v_r * 0.7 + v_r**2 / 1.0 + 0.4
    assert protective_distance(v_r, v_h, led) == pytest.approx(by_hand)
    judge = truth_separation()
    assert (judge.lead_s, judge.speed_margin_mps) == (0.0, 0.0)
    assert judge.reaction_s == pytest.approx(0.3)


@pytest.mark.parametrize("lead_s", [0.0, 0.4])
@pytest.mark.parametrize("v_h", [0.0, 0.15, 0.8, 1.6])
@pytest.mark.parametrize("d", [0.3, 0.45, 0.8, 1.5, 3.0, 6.0])
def test_the_allowed_speed_is_the_largest_with_the_protective_distance_within_reach(
    d: float, v_h: float, lead_s: float
) -> None:
    p = dataclasses.replace(P, lead_s=lead_s)
    v = allowed_speed(d, v_h, p)
    if protective_distance(0.0, v_h, p) >= d:
        assert v == 0.0  # too close even at rest: the protective stop
        return
    assert v > 0.0
    assert protective_distance(v, v_h, p) == pytest.approx(d)
    assert protective_distance(v + 0.01, v_h, p) > d


def test_a_person_walking_faster_towards_the_robot_leaves_it_less_speed() -> None:
    speeds = [allowed_speed(2.0, v_h, P) for v_h in (0.0, 0.5, 1.0, 1.6)]
    assert speeds == sorted(speeds, reverse=True) and speeds[-1] < speeds[0]


def test_a_persons_directed_speed_is_their_velocity_towards_the_robot_plus_the_margin() -> None:
    towards = (1.0, 0.0)  # the robot lies along +x from them
    assert directed_speed((1.0, 0.0), towards, P) == pytest.approx(1.15)
    assert directed_speed((-1.0, 0.0), towards, P) == pytest.approx(0.15)  # walking away
    assert directed_speed((0.0, 1.0), towards, P) == pytest.approx(0.15)  # across
    assert directed_speed(None, towards, P) == 1.6  # not known yet: a walking pace
