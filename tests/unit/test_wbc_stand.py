"""The whole-body controller keeps the MuJoCo robot standing and trotting, in process."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from bench.wbc_harness import (
    Figures,
    floor_spec,
    run_carry,
    run_grasp,
    set_initial_pose,
    simulate,
    summary,
)
from common import robot
from services.wbc.controller import WbcReferences, WbcState, WholeBodyController


def walk(seconds: float, cmd: tuple[float, float, float], payload_kg: float = 0.0) -> Figures:
    model = floor_spec(payload_kg).compile()
    data = mujoco.MjData(model)
    set_initial_pose(model, data, robot.standing_q())

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        return WbcReferences(cmd_vel=np.array(cmd) if t > 0.5 else np.zeros(3))

    log, controller, wall = simulate(model, data, seconds, refs_at)
    out = summary(log, wall)
    out["qp_failures"] = controller.qp_failures
    return out


def test_standing_two_seconds_keeps_base_height_within_a_centimetre() -> None:
    out = walk(2.0, (0.0, 0.0, 0.0))
    assert not out["fell"]
    assert out["height_err_max_m"] < 0.01
    assert abs(out["distance_m"]) < 0.05 and out["drift_m"] < 0.05
    assert out["qp_failures"] == 0


@pytest.mark.slow
def test_trotting_forward_with_a_payload_covers_the_commanded_distance() -> None:
    out = walk(10.5, (0.5, 0.0, 0.0), payload_kg=0.5)
    assert not out["fell"]
    assert 4.0 < out["distance_m"] < 5.5  # 0.5 m/s for 10 s, less the acceleration ramp
    assert out["drift_m"] < 0.2
    assert out["roll_pitch_max_deg"] < 10.0


@pytest.mark.slow
def test_trotting_in_place_turns_at_the_commanded_rate() -> None:
    out = walk(4.5, (0.0, 0.0, 0.5))
    assert not out["fell"]
    assert 1.6 < out["yaw_rad"] < 2.1  # 0.5 rad/s for 4 s, less the ramp
    assert abs(out["distance_m"]) < 0.15 and out["drift_m"] < 0.15


@pytest.mark.slow
def test_trotting_sideways_strafes() -> None:
    out = walk(5.5, (0.0, 0.2, 0.0))
    assert not out["fell"]
    assert 0.8 < out["drift_m"] < 1.1 and abs(out["distance_m"]) < 0.15


@pytest.mark.slow
def test_a_stop_after_a_walk_that_was_held_back_does_not_chase_the_lead() -> None:
    """A walk at 0.25 m/s whose CoM reference is left 0.1 m to the side (a pallet held
    the hips: hall seed 0's shift), then a turn in place: the base may brake, but not walk
    the 0.1 m sideways (before: 0.114 m at up to 0.34 m/s, towards a person)."""
    model = floor_spec().compile()
    data = mujoco.MjData(model)
    set_initial_pose(model, data, robot.standing_q())
    ctrl: list[WholeBodyController] = []

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        if t < 0.5:
            return WbcReferences(cmd_vel=np.zeros(3))
        if t < 2.0:
            if abs(t - 1.9) < 1e-3 and ctrl:  # held back: the lead goes sideways
                ctrl[0].ref_xy[:] = ctrl[0].model.com[:2] + np.array([0.0, 0.1])
            return WbcReferences(cmd_vel=np.array([0.25, 0.0, 0.0]))
        return WbcReferences(cmd_vel=np.array([0.0, 0.0, -0.8 if t < 3.5 else 0.0]))

    log, controller, _ = simulate(model, data, 5.0, refs_at, on_start=ctrl.append)
    pos = np.array(log.pos)
    k0 = int(np.searchsorted(np.array(log.t), 2.0))
    sideways = pos[-1, 1] - pos[k0, 1]
    assert abs(sideways) < 0.05, sideways
    assert pos[:, 2].min() > 0.4 and controller.qp_failures == 0


@pytest.mark.slow
def test_standing_robot_grasps_lifts_and_shakes_the_small_worlds_bottle() -> None:
    out = run_grasp(seed=0)
    assert not out["fell"]
    assert out["held"]
    assert out["bottle_truth_lift_m"] > 0.05
    assert out["bottle_slip_in_tcp_m"] < 0.02


@pytest.mark.slow
def test_a_carried_can_knocked_in_the_jaws_stays_held_through_a_turn_at_the_top_rate() -> None:
    """The shift's slip, twice as hard (40 N sideways for 0.1 s on hall seed 0's can_1,
    the arm stowed), then a turn on the spot at navigation's top rate, 0.8 rad/s: the
    knock sways the can with the arm (0.04 m; 0.01 m unknocked) but it does not move in
    the jaws, and the turn does not shake it out."""
    out = run_carry(0, "hall", "can_1", knock_n=40.0, wz=0.8)
    assert not out["fell"]
    assert out["object_knock_sway_m"] > 0.025, out  # the knock landed
    gap = out["object_tcp_gap_max_m"]
    assert max(gap.values()) - min(gap.values()) < 0.01, gap  # never moved in the jaws
    assert out["held"] and out["yaw_rad"] > 4.0, out  # held through most of a turn
