"""Where a side-grasped cylinder sits in the jaws, from the jaw's angle
(`services.mission.seat`)."""

from __future__ import annotations

import itertools

import pytest

from common import robot
from services.mission.seat import SOFT_RAD, seat_angle, seat_x

#: The harness's hall seed 10 can_3 (r 3.25 cm), grasped with its axis this far along the
#: jaws (m, + toward the tips), and the jaw's angle once it held (rad): the sim's truth.
CAN_3 = 0.0325
MEASURED = [(0.02, -0.6164), (0.01, -0.6898), (0.0, -0.7666), (-0.01, -0.8607)]


@pytest.mark.parametrize(("x_c", "angle"), MEASURED)
def test_the_sim_s_jaw_angles_say_where_the_can_sat_within_3_mm(x_c: float, angle: float) -> None:
    assert seat_x(angle, CAN_3) == pytest.approx(x_c, abs=0.003)


def test_deeper_or_wider_opens_the_jaw_more_and_the_angle_reads_back() -> None:
    angles = [seat_angle(x, CAN_3) for x in (0.02, 0.01, 0.0, -0.01, -0.02)]
    assert all(a > b for a, b in itertools.pairwise(angles))  # deeper: wider
    assert all(robot.GRIPPER_WIDE < a < robot.GRIPPER_CLOSED for a in angles)
    # 0.06-0.12 rad of jaw angle a cm: a seat 1.2 cm off is about 0.1 rad
    assert 0.06 < angles[1] - angles[2] < 0.12
    assert seat_angle(0.0, 0.035) < seat_angle(0.0, 0.0325) < seat_angle(0.0, 0.03)
    for x in (0.015, 0.0, -0.012):
        for r in (0.028, 0.0325, 0.036):
            assert seat_x(seat_angle(x, r) + SOFT_RAD, r) == pytest.approx(x, abs=1e-4)
