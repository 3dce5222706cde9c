"""The sim's push hook: a force on the base for a whole number of steps, from the next one."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import math

import msgspec
import mujoco
import numpy as np
import pytest

from common.keys import WORLD_PUSH
from common.messages import decode, encode
from common.messages.sim import Push
from common.messages.world import WorldDescription
from services.sim.core import PushError, SimCore
from services.sim.hold import StandHold
from services.sim.world import generate_world


@pytest.fixture(scope="module")
def world() -> WorldDescription:
    return generate_world(0, "small")


def robot_momentum(core: SimCore) -> np.ndarray:
    """The whole robot's linear momentum in world, N·s."""
    mujoco.mj_subtreeVel(core.model, core.data)
    body = core.pushes.body_id
    return np.asarray(core.data.subtree_linvel[body] * core.model.body_subtreemass[body])


def step_held(core: SimCore, law: StandHold, n: int) -> None:
    for _ in range(n):
        state = core.robot_state()
        core.command(law.tau_ff, law.q_des, law.v_des, law.kp, law.kd, state.stamp_ns)
        core.step()


def test_a_push_adds_its_impulse_to_the_robot_in_free_flight(world: WorldDescription) -> None:
    core = SimCore(world)
    start = world.robot_start
    core.reset_robot(start.x, start.y, start.yaw)
    core.data.qpos[core._base_q[2]] = 3.0  # high above the floor: no contact for a while
    mujoco.mj_forward(core.model, core.data)
    law = StandHold()
    p0 = robot_momentum(core)
    steps = core.push((0.0, 200.0, 0.0), 0.1)
    assert steps == 100
    step_held(core, law, 100)
    dp = robot_momentum(core) - p0
    gravity = core.model.body_subtreemass[core.pushes.body_id] * 9.81 * 0.1
    assert dp[1] == pytest.approx(20.0, rel=0.01)  # 200 N for 0.1 s
    assert abs(dp[0]) < 0.05
    assert dp[2] == pytest.approx(-gravity, rel=0.01)
    assert not core.pushes.active
    step_held(core, law, 50)  # the push is over: momentum only changes by gravity now
    assert robot_momentum(core)[1] == pytest.approx(p0[1] + 20.0, rel=0.01)


def test_the_force_acts_for_exactly_its_steps_from_the_next_one(world: WorldDescription) -> None:
    core = SimCore(world)
    law = StandHold()
    body = core.pushes.body_id
    core.push((50.0, 0.0, 0.0), 0.0031)  # rounds to 3 steps
    core.push((0.0, -10.0, 0.0), 0.001)  # overlapping pushes add up
    assert not core.data.xfrc_applied[body].any()  # nothing before the next step
    seen = []
    for _ in range(5):
        step_held(core, law, 1)
        seen.append(core.data.xfrc_applied[body, :3].copy())
    np.testing.assert_allclose(seen[0], [50.0, -10.0, 0.0])
    np.testing.assert_allclose(seen[1], [50.0, 0.0, 0.0])
    np.testing.assert_allclose(seen[2], [50.0, 0.0, 0.0])
    np.testing.assert_allclose(seen[3], 0.0)
    np.testing.assert_allclose(seen[4], 0.0)
    assert not core.data.xfrc_applied[body, 3:].any()  # a force at the CoM, no torque


def test_a_standing_robot_held_by_pd_is_moved_sideways_by_a_push(
    world: WorldDescription,
) -> None:
    pushed, still = SimCore(world), SimCore(world)
    law = StandHold()
    pushed.push((0.0, 200.0, 0.0), 0.1)
    step_held(pushed, law, 150)
    step_held(still, law, 150)
    y_pushed = pushed.state_truth().base_position_in_world[1]
    y_still = still.state_truth().base_position_in_world[1]
    assert y_pushed - y_still > 0.005


@pytest.mark.parametrize(
    ("force", "duration"),
    [
        ((math.nan, 0.0, 0.0), 0.1),
        ((0.0, math.inf, 0.0), 0.1),
        ((0.0, 1e300, 0.0), 0.1),  # finite, but it would blow the physics up
        ((1.0, 2.0), 0.1),
        ((1.0, 2.0, 3.0), 0.0),
        ((1.0, 2.0, 3.0), -0.1),
        ((1.0, 2.0, 3.0), 11.0),
        ((1.0, 2.0, 3.0), math.nan),
    ],
)
def test_bad_pushes_are_refused_with_what_was_given(
    world: WorldDescription, force: tuple[float, ...], duration: float
) -> None:
    core = SimCore(world)
    with pytest.raises(PushError):
        core.push(force, duration)
    assert not core.pushes.active


def test_the_push_message_travels_on_the_world_key_and_validates() -> None:
    assert WORLD_PUSH == "dume/world/push"
    msg = Push(stamp_ns=2_000_000_000, force_in_world=(0.0, 200.0, 0.0), duration_s=0.1)
    assert decode(encode(msg), Push) == msg
    bad = msgspec.msgpack.encode(
        {"stamp_ns": 0, "force_in_world": [0.0, 200.0, 0.0], "duration_s": 0.0}
    )
    with pytest.raises(Exception, match="duration_s"):
        decode(bad, Push)
