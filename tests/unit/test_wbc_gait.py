"""The trot's command shaping, swing profiles, schedule and footholds."""

from __future__ import annotations

import numpy as np
import pytest

from common import robot
from common.config import GaitSettings
from services.wbc.gait import TrotGait, bump, quintic, shape_velocity

FEET = np.array(
    [
        [0.3455, 0.19875, 0.04],
        [0.3455, -0.19875, 0.04],
        [-0.3455, 0.19875, 0.04],
        [-0.3455, -0.19875, 0.04],
    ]
)


def test_velocity_shaping_clamps_to_limits_and_acceleration() -> None:
    p = GaitSettings()
    v = np.zeros(3)
    for _ in range(5000):
        v = shape_velocity(np.array([5.0, -5.0, 5.0]), v, 0.001, p)
    np.testing.assert_allclose(v, [p.v_max[0], -p.v_max[1], p.v_max[2]])
    step = shape_velocity(np.array([5.0, 0.0, 0.0]), np.zeros(3), 0.01, p)
    assert step[0] == p.a_max[0] * 0.01
    assert p.v_max[0] >= 0.8 and p.v_max[1] >= 0.4 and p.v_max[2] >= 1.0


def test_profiles_start_and_end_at_rest_and_their_derivatives_match() -> None:
    for f in (quintic, bump):
        for tau in (0.0, 1.0):
            assert abs(f(tau)[1]) < 1e-12 and abs(f(tau)[2]) < 1e-12
        for tau in np.linspace(0.05, 0.95, 7):
            h = 1e-6
            assert abs((f(tau + h)[0] - f(tau - h)[0]) / (2 * h) - f(tau)[1]) < 1e-5
            assert abs((f(tau + h)[1] - f(tau - h)[1]) / (2 * h) - f(tau)[2]) < 1e-4
    assert quintic(1.0)[0] == 1.0 and abs(bump(0.5)[0] - 1.0) < 1e-12


def run(gait: TrotGait, cmd: np.ndarray, seconds: float) -> list[np.ndarray]:
    stances = []
    for _ in range(round(seconds / 0.001)):
        gait.update(0.001, cmd, np.zeros(2), 0.0, np.zeros(3), 0.5, FEET)
        stances.append(gait.stance.copy())
    return stances


def test_trot_alternates_diagonal_pairs_and_stops_with_all_feet_down() -> None:
    gait = TrotGait(GaitSettings())
    assert not gait.walking and gait.stance.sum() == 4
    stances = run(gait, np.array([0.3, 0.0, 0.0]), 1.0)
    swings = {tuple(s) for s in stances}
    assert (0.0, 1.0, 1.0, 0.0) in swings and (1.0, 0.0, 0.0, 1.0) in swings
    run(gait, np.zeros(3), 2.0)
    assert not gait.walking and gait.stance.sum() == 4 and not gait.swing


def test_footholds_step_ahead_when_walking_forward_and_into_a_push() -> None:
    gait = TrotGait(GaitSettings())
    run(gait, np.array([0.5, 0.0, 0.0]), 0.6)
    still = gait.foothold(0, np.zeros(2), 0.0, np.array([0.5, 0.0, 0.0]), 0.5)
    assert still[0] > FEET[0, 0] + 0.05 and abs(still[1] - FEET[0, 1]) < 0.02
    assert still[2] == robot.FOOT_RADIUS_M
    pushed = gait.foothold(0, np.zeros(2), 0.0, np.array([0.5, 0.3, 0.0]), 0.5)
    assert pushed[1] > still[1] + 0.05


def test_braking_is_harder_than_speeding_up() -> None:
    p = GaitSettings(a_max=[1.0, 1.0, 2.0], d_max=[2.0, 2.0, 3.0])
    dt = 0.002
    v = np.zeros(3)
    t_up = 0
    while v[0] < 0.5 - 1e-9:
        v = shape_velocity(np.array([0.5, 0.0, 0.0]), v, dt, p)
        t_up += 1
    t_down = 0
    while v[0] > 1e-9:
        v = shape_velocity(np.zeros(3), v, dt, p)
        t_down += 1
    assert t_up * dt == pytest.approx(0.5, abs=2 * dt)
    assert t_down * dt == pytest.approx(0.25, abs=2 * dt)
    # A reversal brakes to zero at d_max, then speeds up the other way at a_max.
    v = np.array([0.0, 0.4, 0.0])
    v = shape_velocity(np.array([0.0, -0.4, 0.0]), v, dt, p)
    assert v[1] == pytest.approx(0.4 - 2.0 * dt)
