"""The WBC's fast wire conversions agree with `as_numpy`/`to_wire` and refuse bad arrays."""

from __future__ import annotations

import numpy as np
import pytest

from common import robot
from common.messages import Array, ArrayError, as_numpy, decode, encode, to_wire
from common.messages.sim import JointCommand, RobotState
from services.wbc.values import WbcCommand
from services.wbc.wire import joint_command, wbc_state

N = len(robot.JOINT_NAMES)


def state(q: Array) -> RobotState:
    return RobotState(
        stamp_ns=2_000_000,
        tick=2,
        q=q,
        v=to_wire(np.linspace(-1.0, 1.0, N)),
        tau=to_wire(np.zeros(N)),
        foot_contacts=(True, True, True, True),
        foot_forces=(150.0, 150.0, 150.0, 150.0),
        imu_angular_velocity=(0.0, 0.0, 0.0),
        imu_specific_force=(0.0, 0.0, 9.81),
        gripper_angle=0.0,
        gripper_effort=0.0,
    )


def test_state_and_command_round_trip_as_the_generic_helpers_do() -> None:
    q = robot.POSTURES["ready"]
    msg = decode(encode(state(to_wire(q))), RobotState)
    s = wbc_state(msg)
    np.testing.assert_array_equal(s.q, q)
    np.testing.assert_array_equal(s.v, as_numpy(msg.v))
    rng = np.random.default_rng(0)
    tau, q, v, kp, kd = (rng.normal(size=N) for _ in range(5))
    cmd = WbcCommand(tau, q, v, kp, kd, True, "solved", np.ones(4))
    wire = decode(encode(joint_command(7, cmd)), JointCommand)
    for name in ("tau_ff", "q_des", "v_des", "kp", "kd"):
        assert getattr(wire, name) == to_wire(getattr(cmd, name))


@pytest.mark.parametrize(
    "bad",
    [
        Array("float32", (N,), np.zeros(N, np.float32).tobytes()),
        Array("float64", (N - 1,), np.zeros(N - 1).tobytes()),
        Array("float64", (N,), b"\x00" * 8),
    ],
)
def test_a_malformed_joint_vector_is_refused(bad: Array) -> None:
    with pytest.raises(ArrayError):
        wbc_state(state(bad))
