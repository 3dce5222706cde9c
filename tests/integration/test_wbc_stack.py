"""The whole-body controller as a service: sim + wbc over Zenoh in lockstep, short runs.

The long versions are `dume trial …`; these use the same driver (`bench.trial_driver`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.trial_driver import Driver, start_stack
from bench.trials import Figures, Script, pick, reach, straight
from common import robot
from common.bus import RemoteError
from common.messages.sim import Odom
from common.messages.wbc import ArmGoalReply, ArmGoalRequest, Reach, WbcStatus
from tests.conftest import StartStack

pytestmark = pytest.mark.integration

WBC = [
    'sim.world="small"',
    "sim.world_seed=1",
    "sim.cameras=[]",
    "time.participants={}",
    'time.participants.wbc.role="command"',
    "time.participants.wbc.period_s=0.002",
    "time.participants.wbc.latency_s=0.0",
]


def test_the_wbc_keeps_the_robot_standing_at_its_height_in_lockstep(stack: StartStack) -> None:
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=6")
    odom = s.bus.fifo(s.keys.odom, Odom, maxlen=100_000)
    status = s.bus.latest(s.keys.wbc_status, WbcStatus)
    last = status.wait(lambda m: m.stamp_ns >= 5_000_000_000, 120)
    heights = np.array([o.base_position_in_world[2] for o in odom.drain()])
    assert len(heights) > 100
    assert np.all(np.abs(heights - robot.STAND_BASE_HEIGHT_M) < 0.01), (
        heights.min(),
        heights.max(),
    )
    assert last.mode == "stand" and last.qp_failures == 0 and all(last.contacts)
    assert last.base_error_m < 0.01


def test_bad_arm_goals_get_typed_refusals_and_the_service_keeps_running(
    stack: StartStack,
) -> None:
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=60")
    key = s.keys.arm_goal
    reach_goal = Reach(H=tuple(float(x) for x in np.eye(4).ravel()), frame="base", stamp_ns=0)
    with pytest.raises(RemoteError) as refused:
        s.bus.query(key, ArmGoalRequest(goal=reach_goal), ArmGoalReply)
    assert refused.value.error.code == "busy" and "manipulate" in refused.value.error.message
    with pytest.raises(RemoteError) as unknown:
        s.bus.query(key, {"goal": {"type": "posture", "name": "dance"}}, ArmGoalReply)
    assert unknown.value.error.code == "malformed"
    nan_h = [1.0, 0.0, 0.0, 0.0] * 3 + [0.0, 0.0, 0.0, math.nan]
    with pytest.raises(RemoteError) as nan:
        s.bus.query(key, {"goal": {"type": "reach", "H": nan_h, "frame": "world",
                                   "stamp_ns": 0}}, ArmGoalReply)  # fmt: skip
    assert nan.value.error.code == "malformed"
    status = s.bus.latest(s.keys.wbc_status, WbcStatus)
    now = status.wait(lambda m: m.stamp_ns > 0, 60).stamp_ns
    status.wait(lambda m: m.stamp_ns > now + 200_000_000, 60)  # still ticking


def _run(world: str, seed: int, script_of: object) -> tuple[Driver, Figures]:
    with start_stack(world, seed, 0.002) as s:
        d = Driver(s)
        d.start()
        out: Figures = {}
        d.run(script_of(d, out))  # type: ignore[operator]
    return d, out


def _walk_2m(d: Driver, out: Figures) -> Script:
    yield from straight(d, (0.5, 0.0, 0.0), 4.0, out)


@pytest.mark.slow
def test_a_two_metre_walk_ends_near_its_goal_without_drifting() -> None:
    d, out = _run("hall", 3, _walk_2m)
    assert not d.fell
    assert out["final_error_m"] < 0.15 and out["drift_m"] < 0.1, out


@pytest.mark.slow
def test_one_reach_in_the_base_frame_succeeds_within_3_s() -> None:
    _, out = _run("small", 1, lambda d, out: reach(d, out, n=1))
    assert out["succeeded"] == 1 and out["max_time_s"] <= 3.0, out


@pytest.mark.slow
def test_a_bottle_picked_by_its_truth_pose_stays_held_while_walking() -> None:
    d, out = _run("small", 1, lambda d, out: pick(d, out, walk_s=3.0))
    assert out["held"] and not d.fell, out
